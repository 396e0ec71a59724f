//! Supporting neural-network building blocks: dense layers, conv2d, pooling, bilinear resize and warp, activations, Adam
