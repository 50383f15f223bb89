"""Full-space implicit FEM (backward Euler as energy minimisation, warp kernels, CPU and CUDA)."""
