"""Identification of the scaling functions K of the averaged model (paper, Section 4.3).

Imports :mod:`pectoral_gym`; the package never imports this one. The averaged
model reads the identified coefficients as data (``pectoral_gym/data``).
"""
