"""The README example: a Kuramoto group and its order parameter, with a live loop and a snapshot."""

from cogblocks.blocks import Probe
from cogblocks.sim import Diagram, Simulator
from cogblocks.sync import KuramotoGroup, OrderParameter

d = Diagram()
group = d.add("group", KuramotoGroup(omega=[2.72, 2.93, 4.03, 2.15, 3.91, 3.74, 3.28], gain=4.4 / 7))
order = d.add("order", OrderParameter())
d.connect(group.theta, order.theta)
d.add("r", Probe())
d.connect(order.r, "r.u")
print(d.to_mermaid())

sim = Simulator(d, dt=0.01)
trace = sim.run(duration=60.0)
print(f"mean order parameter over the first minute: {trace['r'].mean():.3f}")

snapshot = sim.state_dict()  # everything needed to continue exactly from here
first = sim.run(duration=5.0)
sim.load_state_dict(snapshot)
again = sim.run(duration=5.0)
assert (first["r"] == again["r"]).all()
print(trace.to_pandas().tail(3))
