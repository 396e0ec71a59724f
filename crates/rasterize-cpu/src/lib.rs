//! Tile-sorted, rayon-parallel CPU rasterizer for 3D Gaussians with C arbitrary channels and analytic backward
