//! The serde mirror of `pipeline.ron`: what the file may say, before validation (every field
//! optional where a default applies; `deny_unknown_fields` throughout, so a typo is an error).

use serde::{Deserialize, Deserializer};

use super::{AoMode, AoOccluders, AssetKind, BlockFormat, Container, EncodeQuality, HeightProjection, LodBudget};
use crate::mesh::occlusion::RayDistribution;

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
pub(crate) struct ReportOverrides {
    pub compare_formats: Option<bool>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct HeightOverrides {
    pub projection: Option<HeightProjection>,
    pub size: Option<u32>,
    pub frontal: Option<f32>,
    pub rear: Option<f32>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct TessellateOverrides {
    pub level: Option<u32>,
    pub displace: Option<bool>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct AoOverrides {
    pub size: Option<u32>,
    pub rays: Option<u32>,
    pub mode: Option<AoMode>,
    pub distribution: Option<RayDistribution>,
    #[serde(default, deserialize_with = "explicit")]
    pub max_distance: Option<Option<f32>>,
    pub occluders: Option<AoOccluders>,
    pub ignore_backfaces: Option<bool>,
    pub ground_plane: Option<bool>,
    pub padding: Option<u32>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct PackOverrides {
    pub max_size: Option<u32>,
    pub padding: Option<u32>,
    pub rotate: Option<bool>,
    pub trim: Option<bool>,
    pub power_of_two: Option<bool>,
    pub pages: Option<u32>,
}

/// `Some(None)` is an explicit `None` in the file; `None` is "not given".
fn explicit<'de, D, T>(deserializer: D) -> Result<Option<Option<T>>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<T>::deserialize(deserializer).map(Some)
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct BillboardOverrides {
    pub epsilon: Option<f32>,
    #[serde(default, deserialize_with = "explicit")]
    pub max_planes: Option<Option<u32>>,
    #[serde(default, deserialize_with = "explicit")]
    pub budget: Option<Option<LodBudget>>,
    #[serde(default, deserialize_with = "explicit")]
    pub texel_density: Option<Option<f32>>,
    #[serde(default, deserialize_with = "explicit")]
    pub screen_size: Option<Option<u32>>,
    pub lods: Option<Vec<LodBudget>>,
    pub alpha_cutoff: Option<f32>,
}

#[derive(Deserialize, Default, Clone)]
#[serde(deny_unknown_fields)]
pub(crate) struct AtlasOverrides {
    pub max_size: Option<u32>,
    pub padding: Option<u32>,
    pub power_of_two: Option<bool>,
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
