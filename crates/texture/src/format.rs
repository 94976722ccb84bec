//! What a surface is written as: the block-compression format, the container file and the
//! encoder's speed/quality trade-off (the pipeline's `encode` section names them).

use serde::{Deserialize, Serialize};

/// A block-compression format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum BlockFormat {
    Bc1,
    Bc3,
    Bc4,
    Bc5,
    Bc7,
}

/// The file format textures are written in.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Container {
    Ktx2,
    Dds,
    Pvr,
}

impl Container {
    pub fn extension(self) -> &'static str {
        match self {
            Container::Ktx2 => "ktx2",
            Container::Dds => "dds",
            Container::Pvr => "pvr",
        }
    }
}

/// The channel order of the packed metallic / roughness / occlusion surface.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Packing {
    /// R metallic, G roughness, B occlusion: `mra.*` (cirrus's first order).
    #[default]
    Mra,
    /// R occlusion, G roughness, B metallic: `orm.*`, glTF's and Unreal's order.
    Orm,
}

impl Packing {
    /// The packed surface's file stem.
    pub fn stem(self) -> &'static str {
        match self {
            Packing::Mra => "mra",
            Packing::Orm => "orm",
        }
    }
}

/// Speed/quality trade-off of the block encoder, ordered fastest first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub enum EncodeQuality {
    UltraFast,
    VeryFast,
    Fast,
    Basic,
    Slow,
    /// BC4/BC5: every endpoint pair (the true optimum, about a millisecond a block: for
    /// references); BC1/BC3/BC7 as `Slow`.
    Exhaustive,
}
