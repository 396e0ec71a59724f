//! Gaussian parameter sets (structure of arrays), activations, SH, covariance, 3DGS PLY I/O, Adam and density control
