"""LiCROM: the neural-field subspace (`network`), its training (torch, `train`) and its solver (`plugin`), stepped by
the reduced family's machinery (`solvers.reduced`)."""
