//! What a billboard cloud tells its user and an engine, as types: `report.json` (the asset's
//! figures, each level's: what it draws, its error, atlas or maps, surfaces and bytes; in a
//! chain its switch size and an `Auto` level's choice) and a chain's `lods.json`. Both are
//! written through `serde_json::Value`, whose keys are sorted, so that the files keep the order
//! they have always had whatever the order of the fields here.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::preview::{Hold, SizeFigures};
use crate::summary::ErrorSummary;
use crate::texture::tail::SurfaceInfo;

/// An asset's `report.json`.
#[derive(Clone, Debug, Serialize)]
pub(super) struct AssetReport<'a> {
    pub asset: &'a str,
    pub kind: &'static str,
    pub mesh: String,
    pub faces: usize,
    pub alpha_cutoff: f32,
    #[serde(flatten)]
    pub levels: ReportLevels,
    pub stage_ms: BTreeMap<&'a str, f64>,
    pub warnings: Vec<ErrorSummary>,
}

/// A chain's levels, or the one level's figures (which are the asset's).
#[derive(Clone, Debug, Serialize)]
#[serde(untagged)]
pub(super) enum ReportLevels {
    Chain {
        /// The least share of a 1920 × 1080 viewport's area at which each level is shown (see
        /// `lod_mesh::screen_coverage`), as `lods.gltf` states it.
        screen_coverage: Vec<f32>,
        levels: Vec<LevelReport>,
    },
    One(LevelFigures),
}

/// One level's (or one slot's) part of the report.
#[derive(Clone, Debug, Serialize)]
pub(super) struct LevelReport {
    pub level: u32,
    pub folder: String,
    #[serde(flatten)]
    pub figures: LevelFigures,
    /// An `Auto` level's choice among its candidates.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub auto: Option<AutoReport>,
    /// A chain's level: how far it holds against the source, and where it is shown from.
    #[serde(flatten)]
    pub switch: Option<SwitchFigures>,
}

/// A chain level's switch measurements.
#[derive(Clone, Debug, Serialize)]
pub(super) struct SwitchFigures {
    pub switch_size: u32,
    pub holds_to: Option<u32>,
    pub measured: Vec<SizeFigures>,
}

/// What a level draws and what it costs.
#[derive(Clone, Debug, Serialize)]
pub(super) struct LevelFigures {
    pub representation: Representation,
    pub triangles: u64,
    /// The bytes an engine loads (previews aside), and those the GPU holds (every mip).
    pub bytes: u64,
    pub gpu_bytes: u64,
    pub surfaces: Vec<SurfaceFigures>,
    #[serde(flatten)]
    pub detail: LevelDetail,
}

/// How a level is drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum Representation {
    BillboardCloud,
    Reduced,
    Impostor,
}

/// A surface's figures from the tail, and for a reduced level's map its material's folder.
#[derive(Clone, Debug, Serialize)]
pub(super) struct SurfaceFigures {
    #[serde(flatten)]
    pub info: SurfaceInfo,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub material: Option<String>,
}

/// The figures only one representation has.
#[derive(Clone, Debug, Serialize)]
#[serde(untagged)]
pub(super) enum LevelDetail {
    Cloud(CloudFigures),
    Reduced(ReducedFigures),
    Impostor(ImpostorFigures),
}

/// A billboard-cloud level's planes, quads, error and atlas.
#[derive(Clone, Debug, Serialize)]
pub(super) struct CloudFigures {
    pub planes: usize,
    pub quads: usize,
    /// The quad budget (none: ε decides) and the ε it was met with.
    pub budget_quads: Option<u32>,
    /// Faces of solid materials drawn on another plane's quad too (crack filling).
    pub faces_also_drawn: usize,
    pub epsilon: f32,
    pub epsilon_world: f32,
    pub max_error_world: f32,
    pub mean_error_world: f32,
    pub seam_gap_world: f32,
    pub atlas: CloudAtlas,
}

/// A billboard-cloud level's atlas.
#[derive(Clone, Debug, Serialize)]
pub(super) struct CloudAtlas {
    pub width: u32,
    pub height: u32,
    pub texel_density: f32,
    pub screen_size: Option<u32>,
    /// The share of the atlas its quads take (to 1e-4), and the share of texels covered.
    pub occupancy: f32,
    pub coverage: f64,
}

/// A reduced level's budget, triangles kept and error.
#[derive(Clone, Debug, Serialize)]
pub(super) struct ReducedFigures {
    pub budget: Option<ReducedBudget>,
    pub vertices: u64,
    /// The simplifier's largest deviation: a fraction of the mesh's largest extent, and in world
    /// units.
    pub error: f32,
    pub error_world: f32,
    pub cards: Cards,
    /// The leaf area drawn (cut-out materials), against the source's (to 1e-4).
    pub leaf_area: Option<f64>,
    /// The largest side of its maps.
    pub map_side: u32,
}

/// A reduced level's triangle budget as the report states it.
#[derive(Clone, Copy, Debug, Serialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum ReducedBudget {
    Triangles(u32),
    Ratio(f32),
}

/// Leaf cards in the source and those a reduced level kept.
#[derive(Clone, Copy, Debug, Serialize)]
pub(super) struct Cards {
    pub source: u64,
    pub kept: u64,
}

/// An impostor level's frames and atlas.
#[derive(Clone, Debug, Serialize)]
pub(super) struct ImpostorFigures {
    pub frames: u32,
    pub hemi: bool,
    pub frame_size: u32,
    pub atlas: Side,
}

/// An atlas's size.
#[derive(Clone, Copy, Debug, Serialize)]
pub(super) struct Side {
    pub width: u32,
    pub height: u32,
}

/// An `Auto` level's part of the report: its bytes, the candidate chosen, every candidate's.
#[derive(Clone, Debug, Serialize)]
pub(super) struct AutoReport {
    pub max_bytes: u64,
    pub chosen: Option<String>,
    pub candidates: Vec<CandidateReport>,
}

/// One candidate of an `Auto` level.
#[derive(Clone, Debug, Serialize)]
pub(super) struct CandidateReport {
    pub name: Option<String>,
    pub folder: String,
    pub representation: Representation,
    /// Each surface's side (a reduced level's by material: `bark/albedo`).
    pub surface_sides: BTreeMap<String, u32>,
    pub gpu_bytes: u64,
    /// How far it holds against the source (`holds_to`, `measured`, `outranked_at`).
    #[serde(flatten)]
    pub hold: Hold,
}

/// A chain's `lods.json` for engines.
#[derive(Clone, Debug, Serialize)]
pub(super) struct LodsDocument<'a> {
    pub asset: &'a str,
    /// The bounding sphere whose diameter on screen picks a level.
    pub center: [f32; 3],
    pub radius: f32,
    /// Show level k while the sphere's diameter on screen, in pixels, is at most its switch_size
    /// and more than level k + 1's; above level 0's, the source. A level that never holds
    /// within one px-shift unit has 0.
    pub switch_size_unit: &'static str,
    pub levels: Vec<LodsLevel>,
}

/// One level of `lods.json`.
#[derive(Clone, Debug, Serialize)]
pub(super) struct LodsLevel {
    pub level: u32,
    pub gltf: String,
    pub representation: Representation,
    pub triangles: u64,
    pub gpu_bytes: u64,
    pub switch_size: Option<u32>,
}

/// `document` as pretty JSON with its keys sorted (through `serde_json::Value`).
pub(super) fn sorted_json(document: &impl Serialize) -> Vec<u8> {
    let value = serde_json::to_value(document).expect("reports serialise");
    serde_json::to_vec_pretty(&value).expect("reports serialise")
}

impl LevelReport {
    /// A slot's part of the report (its level, the slot's number until the chain's is known).
    pub fn new(level: u32, folder: String, figures: LevelFigures) -> LevelReport {
        LevelReport { level, folder, figures, auto: None, switch: None }
    }
}

impl SurfaceFigures {
    /// The tail's figures of surfaces outside any material.
    pub fn of(infos: Vec<SurfaceInfo>) -> Vec<SurfaceFigures> {
        infos.into_iter().map(|info| SurfaceFigures { info, material: None }).collect()
    }
}

/// What a chain's file means, for the manifest and the hot-reload batches: the level it belongs
/// to, and an `Auto` candidate's name.
#[derive(Clone, Debug, Serialize)]
struct FileMeaning<'a> {
    lod: u32,
    #[serde(skip_serializing_if = "Option::is_none")]
    candidate: Option<&'a str>,
}

/// A chain's file's meaning ([`FileMeaning`]) as the outputs hold it.
pub(super) fn file_meaning(lod: u32, candidate: Option<&str>) -> serde_json::Value {
    serde_json::to_value(FileMeaning { lod, candidate }).expect("meanings serialise")
}
