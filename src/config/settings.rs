//! The per-asset settings a validated `pipeline.ron` resolves to: what each kind reads (billboard,
//! atlas, packing, AO, height, tessellation, encoding, report), with their defaults.

use std::path::PathBuf;

use serde::Serialize;

pub use crate::kinds::ambient_occlusion::settings::*;
pub use crate::kinds::atlas::settings::*;
pub use crate::kinds::billboard_cloud::settings::*;
pub use crate::kinds::height::settings::*;
pub use crate::kinds::material::settings::*;
pub use crate::packing::PageSettings;
pub use crate::texture::format::{BlockFormat, Container, EncodeQuality};

/// The block formats a kind of surface may be encoded to (the first is the default).
pub(crate) fn allowed_formats(surface: crate::texture::SurfaceKind) -> &'static [BlockFormat] {
    use crate::texture::SurfaceKind;
    match surface {
        SurfaceKind::Albedo => &[BlockFormat::Bc7, BlockFormat::Bc3, BlockFormat::Bc1],
        SurfaceKind::Mra => &[BlockFormat::Bc1, BlockFormat::Bc7],
        SurfaceKind::Normal => &[BlockFormat::Bc5, BlockFormat::Bc7],
        SurfaceKind::Height | SurfaceKind::Ao => &[BlockFormat::Bc4],
    }
}

#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize)]
pub struct EncodeSettings {
    pub albedo: BlockFormat,
    pub mra: BlockFormat,
    pub normal: BlockFormat,
    pub height: BlockFormat,
    pub ao: BlockFormat,
    pub mips: bool,
    pub container: Container,
    /// zstd supercompression level for KTX2 (`None`: no supercompression).
    pub zstd: Option<i32>,
    pub quality: EncodeQuality,
    /// The packed surface's channel order (`mra.*` or `orm.*`); glTF gets ORM either way.
    pub packing: crate::texture::format::Packing,
}

impl EncodeSettings {
    /// The block format of one kind of surface.
    pub(crate) fn format_of(&self, surface: crate::texture::SurfaceKind) -> BlockFormat {
        match surface {
            crate::texture::SurfaceKind::Albedo => self.albedo,
            crate::texture::SurfaceKind::Mra => self.mra,
            crate::texture::SurfaceKind::Normal => self.normal,
            crate::texture::SurfaceKind::Height => self.height,
            crate::texture::SurfaceKind::Ao => self.ao,
        }
    }
}

/// The sections `defaults:` may set, for assets of every kind (and the sections one asset's
/// entry merges before its kind takes its own of them).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Defaults {
    pub billboard: BillboardSettings,
    pub atlas: PageSettings,
    pub pack: PackSettings,
    pub ao: AoSettings,
    pub encode: EncodeSettings,
    pub height: HeightSettings,
    pub report: ReportSettings,
}

/// `KindSettings` and `OwnSettings` of the one list of kinds (`kind_list.rs`).
macro_rules! kind_settings {
    ($($name:ident => $folder:ident),* $(,)?) => {
        /// One asset's kind's own settings (`kinds/<kind>/settings.rs`).
        #[derive(Clone, Debug, PartialEq, Serialize)]
        pub enum KindSettings {
            $($name(crate::kinds::$folder::settings::Settings)),*
        }

        $(impl OwnSettings for crate::kinds::$folder::settings::Settings {
            fn of(settings: &KindSettings) -> Option<&Self> {
                match settings {
                    KindSettings::$name(own) => Some(own),
                    #[allow(unreachable_patterns)]
                    _ => None,
                }
            }
        })*
    };
}

/// A kind's own settings type: found in an asset's settings.
pub trait OwnSettings: Sized {
    fn of(settings: &KindSettings) -> Option<&Self>;
}

with_kinds!(kind_settings);

/// Every setting of one asset, defaults and overrides merged: the shared `encode` section and
/// its kind's own.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Settings {
    pub encode: EncodeSettings,
    pub kind: KindSettings,
}

impl Settings {
    /// The asset's kind's own settings (`settings.own::<billboard_cloud::settings::Settings>()`).
    pub fn own<T: OwnSettings>(&self) -> &T {
        T::of(&self.kind).expect("an asset's settings are of its kind")
    }

    /// The other asset whose output this one reads (a Material's `ao_source`), if any.
    pub fn reads_asset(&self) -> Option<&str> {
        match &self.kind {
            KindSettings::Material(material) => material.ao_source.as_deref(),
            _ => None,
        }
    }

    /// The settings of an asset of `kind` that the sections in `merged` make (its per-asset
    /// fields empty: an asset a rule makes has none).
    pub fn of_kind(kind: crate::config::AssetKind, merged: &Defaults) -> Settings {
        use crate::config::AssetKind;
        use crate::kinds::ambient_occlusion::settings as ambient_occlusion;
        use crate::kinds::atlas::settings as atlas;
        use crate::kinds::billboard_cloud::settings as billboard_cloud;
        use crate::kinds::height::settings as height;
        use crate::kinds::material::settings as material;
        let kind = match kind {
            AssetKind::Material => KindSettings::Material(material::Settings {
                report: merged.report.clone(),
                alpha_cutoff: merged.billboard.alpha_cutoff,
                ao_source: None,
            }),
            AssetKind::BillboardCloud => KindSettings::BillboardCloud(billboard_cloud::Settings {
                billboard: merged.billboard.clone(),
                atlas: merged.atlas.clone(),
            }),
            AssetKind::Atlas => KindSettings::Atlas(atlas::Settings { pack: merged.pack.clone() }),
            AssetKind::AmbientOcclusion => {
                KindSettings::AmbientOcclusion(ambient_occlusion::Settings { ao: merged.ao.clone() })
            }
            AssetKind::Height => KindSettings::Height(height::Settings {
                height: merged.height.clone(),
                tessellate: None,
                high_mesh: PathBuf::new(),
            }),
        };
        Settings { encode: merged.encode.clone(), kind }
    }
}

impl Default for Defaults {
    fn default() -> Defaults {
        Defaults {
            billboard: BillboardSettings::default(),
            atlas: default_billboard_atlas(),
            pack: PackSettings::default(),
            ao: AoSettings::default(),
            encode: EncodeSettings {
                albedo: BlockFormat::Bc7,
                mra: BlockFormat::Bc1,
                normal: BlockFormat::Bc5,
                height: BlockFormat::Bc4,
                ao: BlockFormat::Bc4,
                mips: true,
                container: Container::Ktx2,
                zstd: None,
                quality: EncodeQuality::Basic,
                packing: crate::texture::format::Packing::Mra,
            },
            height: HeightSettings::default(),
            report: ReportSettings::default(),
        }
    }
}
