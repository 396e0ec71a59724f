//! SPyNet-style optical-flow pyramid with exact gradients w.r.t. its input images, weights in safetensors
