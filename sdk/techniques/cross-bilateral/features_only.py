#!/usr/bin/env python3
"""The `features` version of the cross bilateral filter: the weights come
from the spatial distance, normal, albedo and depth only, without the
colour term (see cross_bilateral.py)."""

import cross_bilateral

if __name__ == "__main__":
    cross_bilateral.main(colour_term=False)
