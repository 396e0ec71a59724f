//! Body models (SMPL .npz, built-in CC0 body), forward kinematics, linear blend skinning and the deformation networks
