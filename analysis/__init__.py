"""Analysis: what the results mean. Metrics of a trajectory against its reference, trajectories carried across
meshes, the results table's schema and the figures derived across its rows. Computed here once; `bench` stores
them and `reports` only presents them."""
