"""servobus.sim.devices: simulated device models, one module per protocol family.

Each model speaks its family's sans-IO codec in reverse (it decodes requests and encodes replies with
the same classes the host uses), keeps the RAM state its manual describes, and drives a
:class:`~servobus.sim.plant.Plant` for the mechanics. Models are sans-IO: they take ``now_s`` and
frames (or bytes) and return timed emissions; a :class:`~servobus.sim.network.SimCanNetwork` or a
real-time attachment does the scheduling.
"""
