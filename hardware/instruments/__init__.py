"""PyVISA drivers of the rig's instruments (pyvisa-py ``@py`` backend by default).

Modules
-------
visa          one connection: bounded reads, TCP_NODELAY, unreachable/silent as one-line errors.
power_meter   Keysight EPM N1913A / N1914A (SCPI; ``SYST:ERR?`` after every command).
motion        Newport ESP301 two-axis controller (``TE?`` after every command, bounded waits).
"""
