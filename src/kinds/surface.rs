//! The surfaces that end in the shared texture tail, as the tail, the kinds and the driver name
//! them: an asset's surface by its group and kind, with its label and its files.

use std::path::{Path, PathBuf};

use crate::texture::SurfaceKind;

/// One surface that ends in the texture tail: `group` names what it belongs to inside the asset
/// (a material's name; empty for an asset's own surfaces, like a billboard cloud's atlas), for
/// labels and folders; `part` says the same in numbers, for the kind that made it to read back.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) struct SurfaceId {
    pub group: String,
    pub surface: SurfaceKind,
    pub part: SurfacePart,
}

/// Which part of its asset a surface belongs to, as its kind numbers them (a billboard cloud's
/// level slot and a reduced level's material, an atlas's page; zero where a kind has one part),
/// so that a kind finds the part again without parsing the group's text back.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub(crate) struct SurfacePart {
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
    pub(crate) fn folder(&self, output_folder: &Path) -> PathBuf {
        if self.group.is_empty() {
            output_folder.to_path_buf()
        } else {
            output_folder.join(&self.group)
        }
    }

    /// Its texture and preview files inside the asset folder, named by the surface (a packed
    /// surface by its channel order: `mra` or `orm`) in `encode`'s container.
    pub(crate) fn artifact_paths(&self, output_folder: &Path, encode: &crate::config::EncodeSettings) -> [PathBuf; 2] {
        let folder = self.folder(output_folder);
        let stem = match self.surface {
            SurfaceKind::Mra => encode.packing.stem(),
            surface => surface.name(),
        };
        [folder.join(format!("{stem}.{}", encode.container.extension())), folder.join(format!("{stem}.png"))]
    }

    /// The files of its write stage: its [`SurfaceId::artifact_paths`], and for a packed surface
    /// in `Mra` order the `orm.png` glTF reads.
    pub(crate) fn written_files(&self, output_folder: &Path, encode: &crate::config::EncodeSettings) -> Vec<PathBuf> {
        let mut files = self.artifact_paths(output_folder, encode).to_vec();
        if self.surface == SurfaceKind::Mra && encode.packing == crate::texture::format::Packing::Mra {
            files.push(self.folder(output_folder).join("orm.png"));
        }
        files
    }
}
