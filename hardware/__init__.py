"""hardware: the scanning rig (track, slider, rotation, power meter) through PyVISA.

A probe on a semicircular track of radius R centred at the focus scans the intensity over the
hemisphere: the slider sets theta, the track's rotation about the feed axis sets phi, a
microwave power meter reads the probe. This package drives that rig, or a simulated one on
loopback sockets, and writes what it measured as a FieldMap (method ``measured``).

Modules
-------
rig            kinematics and calibration from ``rig.toml``: (theta, phi) <-> axis positions,
               the probe's true position, limits, the park position.
plan           scan plans from TOML: grid, order (alternating theta sweeps per phi line),
               averaging, drift references; the step list every other module follows.
config         typed, unit-converting TOML table access shared by ``rig`` and ``plan``.
instruments/   PyVISA drivers: ``power_meter`` (Keysight N1913A/N1914A SCPI), ``motion``
               (Newport ESP301), ``visa`` (bounded reads, one-line errors).
journal        append-only, fsynced JSON Lines journal of completed steps; resume rules.
acquire        runs the steps on the instruments, journaling each one.
assemble       journal records -> measured FieldMap (drift removal, standard errors).
drift          receiver gain from the reference readings; removed only when significant.
session        top-level ``scan`` and ``park``, against instruments or the simulator.
interp         bilinear, phi-periodic sampling of a FieldMap between cell centres.
sim/           the simulated rig: ``loopback`` (line-based TCP servers on 127.0.0.1),
               ``instruments`` (protocol models of the N1913A and the ESP301), ``settings``
               (noise, drift, seed, time scale, true calibration), ``rig`` (both instruments
               answering from a FieldMap).
errors         ``PlanError``, ``JournalError`` (and ``InstrumentError`` from raysim.errors).
"""
