"""ppod_sim: the simulated PPOD device (installed from the repository's sim_backend/ folder).

It plays the device side of the CAN protocol, simulates the plate plant, the accelerometers, the
parts (full dynamics) and the overhead camera, and keeps its own clock. Nodes never import it:
they reach it over CAN and topics exactly as they would reach the real device.
"""
