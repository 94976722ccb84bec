//! The `Material` kind: a `.mymaterial` file and the texture maps it names, packed into albedo,
//! mra and normal surfaces that end in the shared texture tail.

pub mod definition;
pub mod channel_packing;
