"""The reduced family's shared machinery: the subspace step (`solver`: `ReducedSolver` on a `Subspace`), its
cubature, term evaluations and warp kernels, the bases that need no network (`bases`: affine, POD), their solvers
(`pod`) and what every reduced solver shares under the contract (`plugin`)."""
