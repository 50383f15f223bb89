"""LiCROM reduced-order solver: neural-field subspace training (torch), cubature, online dynamics (warp kernel)."""
