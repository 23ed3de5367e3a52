"""What one does with a bus's traffic beside the control loop: the DBC exporter, log decoding,
recording.

Layer: above the Bus, below the command line. A tool may import the base, the contracts
(``servobus.protocols``), the scheduler, the transports and the Bus; never the command line, which
imports it.
"""
