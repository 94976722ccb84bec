//! The asset kinds: the one list of kinds, and the questions the driver asks each of them.

pub mod material;
pub mod billboard_cloud;
