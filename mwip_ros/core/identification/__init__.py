"""Identification from a log (docs/theory.md 6.9): the body's parameters (least squares on eq. 1), the raw-sensor fit
and its validation, the drive's constants, and the known excitation that makes a log identifiable.
"""
