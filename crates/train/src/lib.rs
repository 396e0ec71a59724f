//! The E-Sem3DGS method: scene format v1, model assembly, losses, optimisation loop, checkpoints, evaluation
