"""The thin layer that runs the others end to end: nothing below imports it.

Modules:

- ``report``: ``raysim report``: scene -> simulate -> invert -> the paper's Figs. 8-10 in one
  self-contained HTML page.
- ``paper``: the paper's Tables 2 and 3 run with the project's engines and solver.
- ``check``: ``raysim check``: GO against the cheapest accurate wave engine on a dish, per
  frequency, with ``check_inputs`` (the dish, the deformation, the gaps, the engine rule),
  ``check_measures`` (the maps' differences, the bands, the gap signature) and
  ``check_page`` (the HTML page).
- ``budget``: ``raysim budget``: a scan plan's predicted deformation RMS (solver.budget) and
  scan time, per noise level.
- ``campaign``: ``raysim campaign``: a simulated campaign end to end (budget, field, rig scan,
  rim targets, inversion) with the prediction beside the RMS reached.
"""
