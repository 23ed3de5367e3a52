"""servobus.sim: simulated devices, a plant model and a bus model with real timing.

Device and plant models are sans-IO (they take ``now`` and frames, and return frames); the
attachments to a virtual bus or a pseudo-terminal are the only parts that do I/O.
"""
