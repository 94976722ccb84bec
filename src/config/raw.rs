//! The serde mirror of `pipeline.ron`: what the file may say, before validation (every field
//! optional where a default applies; `deny_unknown_fields` throughout, so a typo is an error).

use serde::Deserialize;

use super::sections::explicit;
use super::{
    AoOverrides, AssetKind, AtlasOverrides, BillboardOverrides, BlockFormat, Container, EncodeQuality, HeightOverrides,
    PackOverrides, ReportOverrides, TessellateOverrides,
};

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pipeline {
    pub source: String,
    pub output: String,
    #[serde(default)]
    pub server: Option<String>,
    #[serde(default)]
    pub defaults: SettingsOverrides,
    #[serde(default)]
    pub assets: Vec<Asset>,
    #[serde(default)]
    pub rules: Vec<Rule>,
    #[serde(default)]
    pub limits: Limits,
    #[serde(default)]
    pub cache: Cache,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct Cache {
    /// The shared cache's URL (`s3://bucket/prefix`).
    #[serde(default)]
    pub remote: Option<String>,
    pub mode: Option<crate::cache::remote::RemoteCacheMode>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct Limits {
    /// MiB one texture's working set may take.
    pub texture_memory_mib: Option<u64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct SettingsOverrides {
    #[serde(default)]
    pub billboard: BillboardOverrides,
    #[serde(default)]
    pub atlas: AtlasOverrides,
    #[serde(default)]
    pub pack: PackOverrides,
    #[serde(default)]
    pub ao: AoOverrides,
    #[serde(default)]
    pub height: HeightOverrides,
    #[serde(default)]
    pub encode: EncodeOverrides,
    #[serde(default)]
    pub report: ReportOverrides,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct EncodeOverrides {
    pub albedo: Option<BlockFormat>,
    pub mra: Option<BlockFormat>,
    pub normal: Option<BlockFormat>,
    pub height: Option<BlockFormat>,
    pub ao: Option<BlockFormat>,
    pub mips: Option<bool>,
    pub container: Option<Container>,
    #[serde(default, deserialize_with = "explicit")]
    pub zstd: Option<Option<i32>>,
    pub quality: Option<EncodeQuality>,
    pub packing: Option<crate::texture::format::Packing>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Asset {
    Material {
        name: String,
        material: String,
        /// An `AmbientOcclusion` asset whose maps replace the materials' `ao` textures.
        #[serde(default)]
        ao_source: Option<String>,
        #[serde(default)]
        report: ReportOverrides,
        /// Only its `alpha_cutoff` (an alpha-tested albedo's).
        #[serde(default)]
        billboard: BillboardOverrides,
        #[serde(default)]
        encode: EncodeOverrides,
    },
    BillboardCloud {
        name: String,
        mesh: String,
        #[serde(default)]
        billboard: BillboardOverrides,
        #[serde(default)]
        atlas: AtlasOverrides,
        #[serde(default)]
        encode: EncodeOverrides,
    },
    Atlas {
        name: String,
        textures: Vec<String>,
        #[serde(default)]
        meshes: Vec<String>,
        #[serde(default)]
        pack: PackOverrides,
        #[serde(default)]
        encode: EncodeOverrides,
    },
    AmbientOcclusion {
        name: String,
        mesh: String,
        #[serde(default)]
        ao: AoOverrides,
        #[serde(default)]
        encode: EncodeOverrides,
    },
    Height {
        name: String,
        high: String,
        low: String,
        #[serde(default)]
        height: HeightOverrides,
        #[serde(default)]
        tessellate: Option<TessellateOverrides>,
        #[serde(default)]
        encode: EncodeOverrides,
    },
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rule {
    pub glob: String,
    pub kind: AssetKind,
}
