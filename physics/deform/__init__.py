"""Deformable objects for haptics and sound.

Linear elastostatics by boundary elements (James & Pai, ArtDefo 1999 and Haptics-e 2001):
quadrature (Kelvin kernels, triangle rules), bem (H, G assembly for linear vertex-collocated
triangles, mixed boundary-value solves), greens (reference Green's functions Xi, cached on
disk), capacitance (the capacitance-matrix algorithm with vertex masks), haptic (the 1 kHz
probe loop emitting HapticFrames and a ContactTrack), bench (bench_deform).
"""
