"""Answers built on stored or fresh results: sensitivity indices, tuning, comparisons of isolator
types, floor response, a case's time history and calibration against measured motion.
"""
