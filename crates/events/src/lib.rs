//! Event-camera streams (read/write), voxel grids, an ESIM-style simulator, flow files and event-only flow
