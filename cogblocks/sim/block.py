"""The Block base class: typed ports, explicit state, two-phase tick."""

from __future__ import annotations

import copy
import inspect
import itertools
from collections.abc import Iterator, Mapping
from typing import Any

import numpy as np

from cogblocks.sim.errors import DiagramError
from cogblocks.sim.ports import Input, Output
from cogblocks.sim.signal import Signal, spec_from
from cogblocks.sim.snapshot import generators, value_problem

__all__ = ["Block"]

# creation order of blocks: messages name a user's newest block first, the likeliest to be at fault
_CREATED = itertools.count()


class Block:
    """Base class of every block.

    A block declares its ports and state in ``__init__`` (after calling
    ``super().__init__()``), may finish allocating in :meth:`setup` once its
    input specs and time step are known, and implements the two phases of a
    tick:

    * :meth:`output` computes the outputs of tick ``k`` from the state and the
      *feedthrough* inputs, writing them in place into ``port.value``;
    * :meth:`update` advances the state from tick ``k`` to ``k + 1``.

    Parameters
    ----------
    period : float, optional
        Seconds between two runs of this block. Must be a multiple of the
        diagram's base step; between its runs the block's outputs hold (zero-order
        hold). Defaults to the enclosing diagram's period, or the base step.

    Attributes
    ----------
    dt : float
        The block's own step in seconds (its period), set when compiled.
    every : int
        Base ticks between two runs of the block, set when compiled.
    name : str or None
        The block's name in its diagram.
    """

    #: True for a :class:`~cogblocks.sim.Diagram`: the compiler flattens composite blocks. A flag,
    #: not ``isinstance``, so that the compiler and renderers need not import the diagram module.
    composite: bool = False
    #: True for a block that runs a batch of runs in one call (see :mod:`cogblocks.sim.batch`): its ports then carry
    #: arrays with a leading axis of :attr:`batch` runs and it sizes its state from :attr:`batch_shape` in ``setup``.
    #: Other blocks run in a batch one copy per run. A property where it depends on a part (a policy).
    batchable: bool = False

    def __init__(self, *, period: float | None = None) -> None:
        self._inputs: dict[str, Input] = {}
        self._outputs: dict[str, Output] = {}
        self._state_init: dict[str, Any] = {}
        self._scratch: set[str] = set()
        self.name: str | None = None
        self._parent: Any = None  # the diagram the block was added to; set by Diagram.add
        self.period = period
        self.dt: float = 0.0
        self.every: int = 1
        self.batch: int | None = None  # runs at once, set when compiled; None: no batch axis
        self._created = next(_CREATED)

    # -- declaration ---------------------------------------------------------
    def _check_init(self, name: str) -> None:
        if "_inputs" not in self.__dict__:
            raise TypeError(
                f"{type(self).__name__}.__init__ must call super().__init__() before declaring ports or state"
            )
        if not name.isidentifier():
            raise ValueError(f"port and state names must be Python identifiers, got {name!r}")
        if name in self._inputs or name in self._outputs or name in self._state_init or name in self._scratch:
            raise ValueError(f"{type(self).__name__} already declares {name!r}")
        if name in self.__dict__ or hasattr(type(self), name):
            raise ValueError(f"{type(self).__name__}: {name!r} would shadow an attribute of the block")

    def add_input(
        self,
        name: str,
        spec: Signal | None = None,
        *,
        default: Any = None,
        feedthrough: bool = True,
        **fields: Any,
    ) -> Input:
        """Declare an input port and make it the attribute ``self.<name>``.

        Parameters
        ----------
        name : str
            Port name.
        spec : Signal, optional
            The accepted signal; or give its fields (``shape``, ``dtype``, ``unit``,
            ``wrapped``) as keywords. Fields left ``None`` accept anything.
        default : array_like, optional
            Value read when the input is left unconnected. Without a default, an
            unconnected input is a compile error.
        feedthrough : bool
            Whether :meth:`output` reads this input (default ``True``). Inputs read
            only by :meth:`update` are declared ``feedthrough=False``; this is what
            lets feedback loops through the block compile.
        """
        self._check_init(name)
        spec = spec_from(type(self).__name__, name, spec, fields, Signal())
        port = Input(self, name, spec, default=default, feedthrough=feedthrough)
        fits = ((), port.spec.shape)
        if port.default is not None and port.spec.shape is not None and port.default.shape not in fits:
            if not (type(self).batchable is True and port.default.shape[1:] == port.spec.shape):  # or one row per run
                raise ValueError(
                    f"{type(self).__name__}.{name}: default of shape {port.default.shape} does not fit shape "
                    f"{port.spec.shape}" + (" (or one row per run of a batch)" if type(self).batchable is True else "")
                )
        self._inputs[name] = port
        object.__setattr__(self, name, port)
        return port

    def add_output(
        self,
        name: str,
        spec: Signal | None = None,
        *,
        like: str | None = None,
        initial: Any = None,
        **fields: Any,
    ) -> Output:
        """Declare an output port and make it the attribute ``self.<name>``.

        Parameters
        ----------
        name : str
            Port name.
        spec : Signal, optional
            The produced signal, or its fields as keywords.
        like : str, optional
            Name of an input of this block whose (resolved) spec this output
            copies; keyword fields then override single fields (for instance
            ``like="u", wrapped=False``).
        initial : array_like, optional
            Value of the output before the block first runs and after ``reset``
            (zeros by default).
        """
        self._check_init(name)
        if like is not None:
            if like not in self._inputs:
                raise ValueError(f"{type(self).__name__}.{name}: like={like!r} names no input of the block")
            if spec is not None:
                raise TypeError("give either a spec or like=, not both")
            port = Output(self, name, None, like=like, like_overrides=fields, initial=initial)
        else:
            resolved = spec_from(type(self).__name__, name, spec, fields, Signal())
            if not resolved.concrete:
                raise ValueError(f"{type(self).__name__}.{name}: an output spec must fix every field, got {resolved}")
            port = Output(self, name, resolved, initial=initial)
        self._outputs[name] = port
        object.__setattr__(self, name, port)
        return port

    def add_state(self, name: str, value: Any) -> None:
        """Declare a piece of state, set ``self.<name> = value``, and remember it.

        Declared state is what :meth:`reset` restores and what
        :meth:`state_dict` snapshots. Arrays, numbers and ``numpy.random.Generator``
        objects are supported (a generator is snapshotted by its bit-generator
        state). May be called again in :meth:`setup` to redefine the initial value.
        """
        if name in self._state_init:
            self._state_init[name] = _snapshot(value)
            object.__setattr__(self, name, value)
            return
        self._check_init(name)
        self._state_init[name] = _snapshot(value)
        object.__setattr__(self, name, value)

    def add_scratch(self, name: str, value: Any) -> None:
        """Declare a work attribute, set ``self.<name> = value``: not state, so never snapshotted.

        For what a tick computes and uses within the same tick (a value :meth:`output` computes
        and :meth:`update` commits, a buffer a filter writes into), caches of the state or the
        inputs, and records kept for inspection that the outputs never depend on: a restored
        snapshot must continue bit for bit without it, which :func:`cogblocks.sim.check_block`
        checks. An attribute already set (a parameter a cache overwrites) may be declared too.
        May be called again in :meth:`setup`.
        """
        if name not in self._scratch:
            if name not in self.__dict__ or name in self._inputs or name in self._outputs or name in self._state_init:
                self._check_init(name)
            self._scratch.add(name)
        object.__setattr__(self, name, value)

    # -- introspection -------------------------------------------------------
    @property
    def inputs(self) -> Mapping[str, Input]:
        """The block's input ports by name."""
        return self._inputs

    @property
    def outputs(self) -> Mapping[str, Output]:
        """The block's output ports by name."""
        return self._outputs

    @property
    def parent(self) -> Any:
        """The :class:`~cogblocks.sim.Diagram` this block was added to, or None."""
        return self._parent

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the declared state."""
        return tuple(self._state_init)

    @property
    def scratch_names(self) -> tuple[str, ...]:
        """Names of the declared work attributes (see :meth:`add_scratch`)."""
        return tuple(sorted(self._scratch))

    @property
    def batch_shape(self) -> tuple[int, ...]:
        """The leading axes of this block's signals and state: ``()``, or ``(batch,)`` when it runs a batch at once."""
        return () if self.batch is None else (self.batch,)

    @property
    def stateful(self) -> bool:
        """Whether the block has an ``update`` phase."""
        return type(self).update is not Block.update

    def iter_ports(self) -> Iterator[Input | Output]:
        yield from self._inputs.values()
        yield from self._outputs.values()

    def __repr__(self) -> str:
        ins = ", ".join(self._inputs)
        outs = ", ".join(self._outputs)
        label = f" {self.name!r}" if self.name else ""
        return f"<{type(self).__name__}{label} in=({ins}) out=({outs})>"

    # -- lifecycle -----------------------------------------------------------
    def setup(self) -> None:
        """Finish construction once ``self.dt`` and every input spec are known.

        Called at compile time; the default does nothing. Override it to size
        state from the resolved input specs or to design filters for ``self.dt``.
        """

    def output(self, k: int) -> None:
        """Write the outputs of base tick ``k`` into the output ports' ``value`` arrays."""

    def update(self, k: int) -> None:
        """Advance the state from tick ``k`` to the block's next tick."""

    def linear_feedthrough(self) -> Mapping[tuple[str, str], Any] | None:
        """Direct-feedthrough matrices, for a block whose outputs are affine in its feedthrough inputs.

        Override it in a block whose every output is ``y = c + sum(D[y, u] @ u)`` over its
        feedthrough inputs ``u``, with ``c`` computed from the state and the other inputs and
        each ``D`` constant for the run. Return ``{(output, input): D}``, ``D`` of shape
        (output size, input size) on the flattened signals; omitted pairs are zero. Called
        after :meth:`setup`. An algebraic loop made only of such blocks is solved exactly at
        each tick; the default, ``None``, says the block is not linear, and a loop through it
        is refused.
        """
        return None

    def reset(self) -> None:
        """Restore the declared state and the outputs to their initial values."""
        for name, init in self._state_init.items():
            self._restore(name, init)
        for port in self._outputs.values():
            if port.initial is not None:
                port.value[...] = port.initial
            else:
                port.value[...] = 0

    def state_dict(self) -> dict[str, Any]:
        """A deep copy of the block's declared state and current outputs."""
        return {
            "state": {name: _snapshot(self.__dict__[name]) for name in self._state_init},
            "outputs": {name: port.value.copy() for name, port in self._outputs.items()},
        }

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore what :meth:`state_dict` returned; a snapshot that does not fit changes nothing.

        Raises
        ------
        ValueError
            Naming the state entry or output whose name, shape or dtype does not fit.
        """
        problem = self._state_dict_problem(state)
        if problem:
            raise ValueError(f"{self.name or type(self).__name__}: {problem}")
        for name, value in state["state"].items():
            self._restore(name, value)
        for name, value in state["outputs"].items():
            self._outputs[name].value[...] = value

    def _state_dict_problem(self, state: Any) -> str | None:
        """What makes ``state`` unfit for :meth:`load_state_dict`, or None."""
        try:
            saved_state, saved_outputs = state["state"], state["outputs"]
        except (KeyError, TypeError):
            return "not a block state dict (a mapping with 'state' and 'outputs')"
        if set(saved_state) != set(self._state_init) or set(saved_outputs) != set(self._outputs):
            return (
                f"state dict has state {sorted(saved_state)} and outputs {sorted(saved_outputs)}, "
                f"the block has {sorted(self._state_init)} and {sorted(self._outputs)}"
            )
        for name, value in saved_state.items():
            problem = value_problem(self.__dict__.get(name), self._state_init[name], value)
            if problem:
                return f"state {name!r} {problem}"
        for name, value in saved_outputs.items():
            arr = self._outputs[name].value
            problem = value_problem(arr, arr, value)
            if problem:
                return f"output {name!r} {problem}"
        return None

    def _restore(self, name: str, value: Any) -> None:
        """Set a declared state, in place where possible so outside references to it stay valid."""
        current = self.__dict__.get(name)
        if isinstance(current, np.random.Generator):
            current.bit_generator.state = copy.deepcopy(value)
        elif generators(current) and isinstance(value, list) and len(value) == len(current):
            for generator, saved in zip(current, value, strict=True):  # one generator per run of a batch
                generator.bit_generator.state = copy.deepcopy(saved)
        elif (
            isinstance(current, np.ndarray)
            and isinstance(value, np.ndarray)
            and current.shape == value.shape
            and current.dtype == value.dtype
        ):
            current[...] = value
        else:
            object.__setattr__(self, name, copy.deepcopy(value))

    # -- helpers for subclasses ----------------------------------------------
    def _fail(self, message: str) -> DiagramError:
        return DiagramError(f"{self.name or type(self).__name__}: {message}")

    # -- the constructor call, for files -------------------------------------
    def __new__(cls, *args: Any, **kwargs: Any) -> Block:
        # Remember how the block was built so a diagram can be written as plain data
        # (cogblocks.experiments.files). Unpickling and deepcopy call __new__ without arguments
        # and then restore __dict__, which brings the original call back.
        self = super().__new__(cls)
        object.__setattr__(self, "_init_call", (args, kwargs))
        return self

    @property
    def init_arguments(self) -> dict[str, Any]:
        """The arguments the block was constructed with, by parameter name (defaults left out).

        Extra keywords taken by a ``**kwargs`` parameter appear under their own names.

        Raises
        ------
        TypeError
            If the constructor takes ``*args``: such a call has no names to store.
        """
        args, kwargs = self.__dict__.get("_init_call", ((), {}))
        signature = inspect.signature(type(self).__init__)
        bound = signature.bind(self, *args, **kwargs)
        found: dict[str, Any] = {}
        for name, value in list(bound.arguments.items())[1:]:
            kind = signature.parameters[name].kind
            if kind is inspect.Parameter.VAR_POSITIONAL:
                raise TypeError(f"{type(self).__name__}: a constructor with *{name} cannot be described by names")
            if kind is inspect.Parameter.VAR_KEYWORD:
                found.update(value)
            else:
                found[name] = value
        return found


def _snapshot(value: Any) -> Any:
    if isinstance(value, np.random.Generator):
        return copy.deepcopy(value.bit_generator.state)
    if generators(value):
        return [copy.deepcopy(g.bit_generator.state) for g in value]
    return copy.deepcopy(value)
