"""Identification of the scaling functions K of the averaged model (paper, Section 4.3).

Imports :mod:`pectoral_gym`; the package never imports this one. The averaged
model reads the identified coefficients as data (``pectoral_gym/data``).
"""

if __name__ != "pectoral_gym.scaling":  # one module identity (pip install -e . maps this folder there too)
    raise ImportError(f"import pectoral_gym.scaling, not {__name__}: the repository's scaling/ folder is installed as "
                      "pectoral_gym.scaling; importing it by another name would load a second copy of its modules")
