//! The surfaces that end in the shared texture tail, as the tail, the kinds and the driver name
//! them: an asset's surface by its group and kind, with its label and its files, and the plan
//! its kind gives the tail for it.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::cache::CacheKey;
use crate::db::{Asset, Db};
use crate::diagnostic::Diagnostic;
use crate::texture::tail::TailSettings;
use crate::texture::{SurfaceKind, Texture};

/// One surface that ends in the texture tail: `group` names what it belongs to inside the asset
/// (a material's name; empty for an asset's own surfaces, like a billboard cloud's atlas), for
/// labels and folders; `part` says the same in numbers, for the kind that made it to read back.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SurfaceId {
    pub group: String,
    pub surface: SurfaceKind,
    pub part: SurfacePart,
}

/// Which part of its asset a surface belongs to, as its kind numbers them (a billboard cloud's
/// level slot and a reduced level's material, an atlas's page; zero where a kind has one part),
/// so that a kind finds the part again without parsing the group's text back.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct SurfacePart {
    pub index: u32,
    pub item: Option<u32>,
}

impl SurfaceId {
    /// The surface `surface` of the group `group`, the kind's only part of that name.
    pub fn new(group: impl Into<String>, surface: SurfaceKind) -> SurfaceId {
        SurfaceId { group: group.into(), surface, part: SurfacePart::default() }
    }

    /// The same part's surface `surface` (another of its surfaces).
    pub fn sibling(&self, surface: SurfaceKind) -> SurfaceId {
        SurfaceId { surface, ..self.clone() }
    }

    /// The instance label of the surface's tail stages: `asset/group/surface` or `asset/surface`.
    pub fn label(&self, asset_name: &str) -> String {
        format!("{asset_name}/{}", self.instance())
    }

    /// The surface's name inside its asset: `group/surface` or `surface`.
    pub fn instance(&self) -> String {
        if self.group.is_empty() {
            self.surface.name().to_string()
        } else {
            format!("{}/{}", self.group, self.surface.name())
        }
    }

    /// The folder of its files: the asset folder, or its group's inside it.
    pub fn folder(&self, output_folder: &Path) -> PathBuf {
        if self.group.is_empty() {
            output_folder.to_path_buf()
        } else {
            output_folder.join(&self.group)
        }
    }

    /// Its texture and preview files inside the asset folder, named by the surface (a packed
    /// surface by its channel order: `mra` or `orm`) in `encode`'s container.
    pub fn artifact_paths(&self, output_folder: &Path, encode: &crate::config::EncodeSettings) -> [PathBuf; 2] {
        let folder = self.folder(output_folder);
        let stem = match self.surface {
            SurfaceKind::Mra => encode.packing.stem(),
            surface => surface.name(),
        };
        [folder.join(format!("{stem}.{}", encode.container.extension())), folder.join(format!("{stem}.png"))]
    }

    /// The files of its write stage: its [`SurfaceId::artifact_paths`], and for a packed surface
    /// in `Mra` order the `orm.png` glTF reads.
    pub fn written_files(&self, output_folder: &Path, encode: &crate::config::EncodeSettings) -> Vec<PathBuf> {
        let mut files = self.artifact_paths(output_folder, encode).to_vec();
        if self.surface == SurfaceKind::Mra && encode.packing == crate::texture::format::Packing::Mra {
            files.push(self.folder(output_folder).join("orm.png"));
        }
        files
    }
}

/// One of a kind's answers about one of its surfaces (`db`, the asset, the surface).
pub type SurfaceFn<T> = fn(&dyn Db, Asset, &SurfaceId) -> Result<T, Diagnostic>;

/// What the tail needs of a surface, as its kind plans it in one answer (`Kind::surface_plan`):
/// its tail settings and the surface that cuts it out, and the kind's functions that name its
/// recipe and its parts and make its image, which the tail calls only when it needs them (a
/// surface whose recipe the persistent cache holds never asks for its parts or its image).
#[derive(Clone, Debug)]
pub struct SurfacePlan {
    pub settings: TailSettings,
    /// The surface whose alpha test cuts this one out (an atlas's albedo, for the atlas's other
    /// surfaces; the albedo itself): the tail encodes the blocks it hides entirely at the
    /// fastest setting (see `texture::encode::HiddenBlocks`). None: every block is shown. The
    /// recipe and parts keys must then also name what that surface's alpha is made of (the
    /// billboard's parts key holds the atlas coverage, which is where its albedo's alpha is not 0).
    pub cutting: Option<SurfaceId>,
    /// A key for what the image is made of, cheap to compute (source hashes and settings), so
    /// that a surface already in the persistent cache needs no image at all.
    pub recipe: SurfaceFn<Option<CacheKey>>,
    /// A key for what the image is put together from, asked when the recipe missed: dearer (it
    /// may run the stages before the image) but cheaper than the image, and finer than the
    /// recipe (an edit that leaves this surface's parts alone finds it), or none.
    pub parts: SurfaceFn<Option<CacheKey>>,
    /// The surface's image.
    pub image: SurfaceFn<Arc<Texture>>,
}

impl SurfacePlan {
    /// A plan with `settings` whose image `image` makes and whose recipe `recipe` names, with no
    /// parts key and no surface that cuts it out.
    pub fn new(settings: TailSettings, recipe: SurfaceFn<Option<CacheKey>>, image: SurfaceFn<Arc<Texture>>) -> Self {
        SurfacePlan { settings, cutting: None, recipe, parts: |_, _, _| Ok(None), image }
    }
}

impl PartialEq for SurfacePlan {
    fn eq(&self, other: &Self) -> bool {
        self.settings == other.settings
            && self.cutting == other.cutting
            && std::ptr::fn_addr_eq(self.recipe, other.recipe)
            && std::ptr::fn_addr_eq(self.parts, other.parts)
            && std::ptr::fn_addr_eq(self.image, other.image)
    }
}

impl Eq for SurfacePlan {}
