"""Shared numba settings for ugen kernels."""

#: fastmath without 'nnan'/'ninf', so NaN/Inf checks stay valid; reassociation lets
#: reductions across modes vectorise.
FASTMATH = {"reassoc", "contract", "nsz", "arcp"}
