"""``cogblocks live sync|phase|l1`` and ``cogblocks replay``: a ready diagram on real LSL streams, or on a recording."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from cogblocks.cli_options import POLICY, PORT, STEP, output_type, write_safely
from cogblocks.sim.timing import BASE_STEP

__all__ = ["add_live_parser"]

DT = BASE_STEP  # the ready diagrams run at the base step
SCOPE_PORT = 8765
_HELPS = {
    "phase": "a 1-channel position stream (mm) in, its estimated phase (rad) out",
    "sync": "the participants' phases (rad, one channel each) in, the avatar's phase θ_L2 out",
    "l1": "a 3-channel marker stream (mm) in, the L1 avatar's delay-compensated position out",
}


def _options(args: argparse.Namespace) -> dict[str, Any]:
    """The diagram and its options, as a session file keeps them."""
    keep = {"diagram": args.diagram, "in": args.in_stream, "out": args.out_stream, "timeout": args.timeout}
    for key in ("group", "policy", "blender", "delay", "unit"):
        if getattr(args, key, None) is not None:
            keep[key] = getattr(args, key)
    return keep


def _print(args: argparse.Namespace, report: Any, what: str) -> None:
    result = report.summary()
    if args.json:
        print(json.dumps(result), flush=True)
        return
    stopped = " (stopped by Ctrl-C)" if report.interrupted else ""
    print(
        f"{what}: {result['ticks']} ticks at 100 Hz"
        f"{stopped}, {result['late_ticks']} late; tick p50 {result['tick_ms_p50']:.2f} ms, "
        f"p99 {result['tick_ms_p99']:.2f} ms; {result['samples_in']} samples in, {result['samples_out']} out; "
        f"oldest sample used {result['max_age_ms']:.1f} ms"
    )


def _run_live(args: argparse.Namespace) -> int:
    try:
        from cogblocks.data.xdf_write import RecordingError
        from cogblocks.live.ready import live_diagram
        from cogblocks.live.runner import run_realtime, save_report
        from cogblocks.live.session import SessionRecorder
    except ImportError as exc:
        raise ValueError(f'cogblocks live needs the live extra: pip install -e ".[live]" ({exc})') from None
    options = _options(args)
    try:
        compiled = live_diagram(options).compile(DT)
    except KeyboardInterrupt:
        return 130
    recorder = scope = report = None
    try:
        if args.record:  # written as the run goes: a crash loses half a second at most
            recorder = SessionRecorder(args.record, compiled, options)
        if args.scope is not None:
            from cogblocks.live.scope import Scope

            scope = Scope.for_diagram(compiled, port=args.scope, title=f"cogblocks live {args.diagram}")
            print(f"scope at {scope.url}", file=sys.stderr, flush=True)
        report = run_realtime(
            compiled,
            args.duration,
            1.0 / DT,
            record=bool(args.save),
            record_raw=bool(args.save),
            scope=scope,
            recorder=recorder,
        )
    finally:
        for block in compiled.blocks.values():
            if hasattr(block, "close"):
                block.close()
        if scope is not None:
            scope.close()
        if recorder is not None and report is None:  # the run failed: what it recorded stays in the file
            try:
                recorder.close(interrupted=True)
            except RecordingError as exc:
                print(f"cogblocks: error: {exc}", file=sys.stderr)
    code = 0
    if recorder is not None:
        try:
            recorder.close(report.interrupted)
        except RecordingError as exc:
            print(f"cogblocks: error: {exc}", file=sys.stderr)
            code = 1
    _print(args, report, f"{args.diagram} live, {args.in_stream!r} -> {args.out_stream!r}")
    if args.save:  # a live session cannot be repeated: if the file fails, the session goes to a temporary file
        write_safely(args.save, lambda path: save_report(report, path), "the live session")
    if not args.json:
        if args.save:
            print(f"saved the trace and the raw samples to {args.save}")
        if args.record and code == 0:
            print(f"recorded the session to {args.record}")
    return code


def _run_replay(args: argparse.Namespace) -> int:
    try:
        from cogblocks.live.ready import live_diagram
        from cogblocks.live.replay import load_session, replay_session
        from cogblocks.live.runner import save_report
    except ImportError as exc:
        raise ValueError(f'cogblocks replay needs the live extra: pip install -e ".[live]" ({exc})') from None
    session = load_session(args.file)
    recorded = session.options
    options = dict(recorded) if recorded.get("diagram") == args.diagram else {"diagram": args.diagram}
    for key, value in (("in", args.in_stream), ("out", args.out_stream)):
        if value is not None:
            options[key] = value
        elif key not in options:
            raise ValueError(f"{args.file}: recorded with no {args.diagram!r} diagram; give --{key}")
    for key in ("group", "policy", "blender", "delay", "unit"):
        if getattr(args, key, None) is not None:
            options[key] = getattr(args, key)
    report = replay_session(live_diagram(options), session)
    _print(args, report, f"{args.diagram} replayed from {args.file}")
    if args.save:
        write_safely(args.save, lambda path: save_report(report, path), "the replayed run")
    if args.save and not args.json:
        print(f"saved the trace to {args.save}")
    return 0


def _run_view(args: argparse.Namespace) -> int:
    import time

    from cogblocks.live.scope import ScopeView
    from cogblocks.live.view import load_run

    skipped: list[str] = []
    t, signals, units, late = load_run(args.file, skipped)
    for line in skipped:  # what the page cannot draw, named
        print(f"cogblocks view: not shown: {line}", file=sys.stderr, flush=True)
    scope = ScopeView(t, signals, units, late, port=args.port, title=f"cogblocks view {args.file}")
    print(f"view of {args.file} at {scope.url} (Ctrl-C stops)", flush=True)
    try:
        while True:
            time.sleep(0.5)
    except KeyboardInterrupt:
        pass
    finally:
        scope.close()
    return 0


def _diagram_options(p: argparse.ArgumentParser, name: str, replay: bool) -> None:
    recorded = " (default: as recorded)" if replay else ""
    if name == "sync":
        p.add_argument(
            "--group", type=int, choices=(1, 2, 3), default=None if replay else 1, help=f"Table 2's group{recorded}"
        )
        p.add_argument(
            "--policy",
            type=POLICY,
            default=None if replay else "dqn",
            help=f"motion computer, e.g. dqn, lookahead or mean{recorded or ' (default dqn)'}",
        )
        p.add_argument(
            "--blender",
            choices=("continuous", "deliverable"),
            default=None if replay else "continuous",
            help="'continuous': the avatar never jumps; 'deliverable': the deliverable's exact blender"
            f"{recorded or ' (default continuous)'}",
        )
    else:
        p.add_argument(
            "--unit",
            choices=("m", "cm", "mm"),
            help="unit of an input stream that declares none (without it: taken as mm, with a warning)",
        )
    if name == "l1":
        p.add_argument(
            "--delay",
            type=float,
            default=None if replay else 0.1,
            help=f"delay to compensate, seconds{recorded or ' (default 0.1)'}",
        )


def add_live_parser(commands: argparse._SubParsersAction) -> None:
    """Add the ``live`` and ``replay`` commands to the ``cogblocks`` command line's sub-commands."""
    live = commands.add_parser("live", help="run a ready diagram on real LSL streams in real time (100 Hz)")
    diagrams = live.add_subparsers(dest="diagram", metavar="DIAGRAM")
    live.set_defaults(handler=lambda _: live.print_help() or 2)
    for name, text in _HELPS.items():
        p = diagrams.add_parser(name, help=text, description=text)
        p.add_argument("--in", dest="in_stream", required=True, metavar="STREAM", help="name of the input stream")
        p.add_argument("--out", dest="out_stream", required=True, metavar="STREAM", help="name of the output stream")
        p.add_argument("--duration", type=STEP, required=True, metavar="S", help="seconds to run (Ctrl-C stops)")
        p.add_argument("--timeout", type=STEP, default=5.0, metavar="S", help="seconds to wait for the input stream")
        p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
        # outputs are checked before the run: a session is not run to be lost at its end
        p.add_argument(
            "--save",
            type=output_type((".npz",)),
            metavar="FILE",
            help="save the trace and the raw input samples to FILE (.npz)",
        )
        p.add_argument(
            "--record",
            type=output_type((".xdf",)),
            metavar="FILE",
            help="record the session (every stream read and written, tick clocks) to FILE (.xdf, read by pyxdf)",
        )
        p.add_argument(
            "--scope",
            nargs="?",
            const=SCOPE_PORT,
            type=PORT,
            metavar="PORT",
            help=f"serve a page that plots the run on http://127.0.0.1:PORT/ (default port {SCOPE_PORT})",
        )
        _diagram_options(p, name, replay=False)
        p.set_defaults(handler=_run_live)

    rep = commands.add_parser(
        "replay", help="run a ready diagram offline on a session recorded with cogblocks live --record"
    )
    rep.add_argument("file", metavar="FILE", help="the session file (.xdf)")
    kinds = rep.add_subparsers(dest="diagram", metavar="DIAGRAM")
    rep.set_defaults(handler=lambda _: rep.print_help() or 2)
    for name, text in _HELPS.items():
        p = kinds.add_parser(name, help=text, description=f"replay: {text}")
        p.add_argument("--in", dest="in_stream", metavar="STREAM", help="input stream (default: as recorded)")
        p.add_argument("--out", dest="out_stream", metavar="STREAM", help="output stream (default: as recorded)")
        p.add_argument("--json", action="store_true", help="print one JSON object instead of text")
        p.add_argument("--save", type=output_type((".npz",)), metavar="FILE", help="save the trace to FILE (.npz)")
        _diagram_options(p, name, replay=True)
        p.set_defaults(handler=_run_replay)

    view = commands.add_parser(
        "view", help="show a saved run (.npz from --save), a session or any XDF file (LabRecorder's) in the browser"
    )
    view.add_argument("file", metavar="TRACE", help="a trace saved by --save (.npz), a session or any XDF file (.xdf)")
    view.add_argument("--port", type=PORT, default=SCOPE_PORT, help=f"port on 127.0.0.1 (default {SCOPE_PORT})")
    view.set_defaults(handler=_run_view)
