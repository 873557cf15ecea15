"""What a study asks of a machine: criteria and their limits, floor spectra and VC curves, objectives
and constraints, and the designs (sampling plans) that choose its cases.
"""
