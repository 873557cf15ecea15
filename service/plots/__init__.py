"""Figures of studies, cases, comparisons, floor spectra, sensitivity indices and calibrations."""
