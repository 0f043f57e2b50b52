"""The simulated rig: instruments that speak the real protocols on loopback sockets.

Modules:

- ``loopback``: line-based TCP servers on 127.0.0.1.
- ``instruments``: protocol models of the N1913A power meter and the ESP301 controller.
- ``settings``: the simulator's noise, drift, seed, time scale and true calibration.
- ``rig``: both instruments answering from a FieldMap (:class:`SimulatedRig`).
"""
