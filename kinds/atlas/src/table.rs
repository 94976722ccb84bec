//! The atlas table (`atlas.json`, DESIGN §3.5): where each entry lies on which page, and the UV
//! transform that takes a texture coordinate of the source texture onto the page:
//! `uv' = uv_offset + uv × uv_scale` for an entry as it was, and for a turned one
//! `u' = uv_offset.u + v × uv_scale.u`, `v' = uv_offset.v − u × uv_scale.v` (UVs as OBJ has
//! them: origin bottom-left, v up). An alias (another texture with the same kept pixels) shares
//! its entry's rectangle with a transform of its own: its canvas and trim offset may differ.

use crate::packing::Placement;

use super::page::TrimRect;

/// One page of the atlas: its texture file (in the asset's folder) and size.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct AtlasPage {
    pub file: String,
    pub width: u32,
    pub height: u32,
}

/// One entry: a source texture (and the others with the same pixels, `aliases`), trimmed to
/// `width` × `height` texels at `trim_offset` of its `source_size`, placed at `x`, `y` on
/// `page`, turned when `rotated`.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AtlasEntry {
    pub name: String,
    pub page: u32,
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
    pub rotated: bool,
    pub source_size: [u32; 2],
    pub trim_offset: [u32; 2],
    pub uv_offset: [f64; 2],
    pub uv_scale: [f64; 2],
    pub aliases: Vec<AtlasAlias>,
}

/// A texture that shows the entry's pixels from a canvas of its own: where they lie in it and
/// its own UV transform onto the shared rectangle.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AtlasAlias {
    pub name: String,
    pub source_size: [u32; 2],
    pub trim_offset: [u32; 2],
    pub uv_offset: [f64; 2],
    pub uv_scale: [f64; 2],
}

/// The table: pages, then entries in name order.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Table {
    pub pages: Vec<AtlasPage>,
    pub entries: Vec<AtlasEntry>,
}

/// How a source texture's coordinates land on a page (see the module's formulas).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    pub rotated: bool,
    pub uv_offset: [f64; 2],
    pub uv_scale: [f64; 2],
}

impl UvTransform {
    /// The transform of a `source_size` texture trimmed to `trim`, placed at `placement` on a
    /// `page_size` page.
    pub fn of(placement: &Placement, trim: TrimRect, source_size: [u32; 2], page_size: (u32, u32)) -> UvTransform {
        let (page_width, page_height) = (page_size.0 as f64, page_size.1 as f64);
        let (source_width, source_height) = (source_size[0] as f64, source_size[1] as f64);
        let (x, y) = (placement.x as f64, placement.y as f64);
        let (trim_x, trim_y) = (trim.x as f64, trim.y as f64);
        let (uv_offset, uv_scale) = if placement.rotated {
            // The source's X axis runs down the page, its Y axis (up) to the right.
            let offset =
                [(x + placement.height as f64 + trim_y - source_height) / page_width, 1.0 - (y - trim_x) / page_height];
            (offset, [source_height / page_width, source_width / page_height])
        } else {
            let offset = [(x - trim_x) / page_width, 1.0 - (y - trim_y + source_height) / page_height];
            (offset, [source_width / page_width, source_height / page_height])
        };
        UvTransform { rotated: placement.rotated, uv_offset, uv_scale }
    }

    /// A source texture coordinate on the page.
    pub fn page_uv(&self, uv: [f64; 2]) -> [f64; 2] {
        if self.rotated {
            [self.uv_offset[0] + uv[1] * self.uv_scale[0], self.uv_offset[1] - uv[0] * self.uv_scale[1]]
        } else {
            [self.uv_offset[0] + uv[0] * self.uv_scale[0], self.uv_offset[1] + uv[1] * self.uv_scale[1]]
        }
    }
}

impl AtlasEntry {
    /// The entry's own texture's transform.
    pub fn transform(&self) -> UvTransform {
        UvTransform { rotated: self.rotated, uv_offset: self.uv_offset, uv_scale: self.uv_scale }
    }

    /// A source texture coordinate of the entry's own texture on the page.
    pub fn page_uv(&self, uv: [f64; 2]) -> [f64; 2] {
        self.transform().page_uv(uv)
    }
}

impl AtlasAlias {
    pub fn transform(&self, rotated: bool) -> UvTransform {
        UvTransform { rotated, uv_offset: self.uv_offset, uv_scale: self.uv_scale }
    }
}

impl Table {
    /// `atlas.json`: pretty JSON with a final newline.
    pub fn to_json(&self) -> String {
        let mut json = serde_json::to_string_pretty(self).expect("the table serialises");
        json.push('\n');
        json
    }
}
