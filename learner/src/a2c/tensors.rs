//! Reading tch tensors into plain Rust values, shared by the tch reference
//! network and the project's own kernels (a leaf module: it imports nothing
//! of the crate).

use tch::{Kind, Tensor};

/// The values of a float tensor.
pub fn floats(t: &Tensor) -> Vec<f32> {
    Vec::<f32>::try_from(&t.to_kind(Kind::Float).contiguous().flatten(0, -1))
        .expect("invariant: a float tensor converts to Vec<f32>")
}
