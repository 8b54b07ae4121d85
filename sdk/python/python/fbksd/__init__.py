"""FBKSD Python SDK: write sampling and denoising techniques for Monte Carlo rendering.

``fbksd.client`` is the technique API (thesis appendix B, plus adaptive
sampling and count requests). The native part is ``fbksd._native``, built
from ``sdk/python`` in the FBKSD repository.
"""

__version__ = "0.1.0"
