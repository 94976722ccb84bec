//! What a build reports: the `build --summary json` contract of DESIGN §6, its text rendering,
//! the stage statuses it is made of.

use std::fmt::Write;

use serde::Serialize;

use crate::diagnostic::{display_path, Diagnostic};

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct BuildSummary {
    pub revision: u64,
    pub assets: Vec<AssetSummary>,
    /// Artifacts whose bytes this build changed (written or renamed into place), in path order.
    #[serde(skip)]
    pub changed: Vec<ChangedArtifact>,
    /// Artifacts this build deleted (their asset left the pipeline or stopped producing them).
    #[serde(skip)]
    pub removed: Vec<String>,
}

/// An artifact a build wrote: what a running engine must reload.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct ChangedArtifact {
    /// What the file is for an engine (absent in manifests written before roles).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub role: Option<ArtifactRole>,
    pub asset: String,
    /// The file inside the asset's folder, e.g. `oak_bark/albedo.ktx2`.
    pub artifact: String,
    /// Relative to the folder of `pipeline.ron`.
    pub path: String,
    /// blake3 hex digest of the file.
    pub hash: String,
    /// What the file's values mean, where its kind says (a height map's mapping, the LOD level
    /// of a chain's file), as the manifest lists it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub meaning: Option<serde_json::Value>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AssetStatus {
    Ok,
    Failed,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum StageStatus {
    Ran,
    /// From memory or the local persistent cache.
    Cached,
    /// From the shared cache (see `stage_summaries` in the driver for stages with no entry).
    Remote,
    Failed,
}

impl StageStatus {
    pub fn name(self) -> &'static str {
        match self {
            StageStatus::Ran => "ran",
            StageStatus::Cached => "cached",
            StageStatus::Remote => "remote",
            StageStatus::Failed => "failed",
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StageSummary {
    pub stage: String,
    pub instance: String,
    pub status: StageStatus,
    pub ms: f64,
}

#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct ArtifactSummary {
    /// Relative to the folder of `pipeline.ron`.
    pub path: String,
    /// blake3 hex digest.
    pub hash: String,
}

#[derive(Clone, Debug, PartialEq, Eq, Serialize, serde::Deserialize)]
pub struct ErrorSummary {
    pub file: String,
    pub line: Option<u32>,
    pub column: Option<u32>,
    pub message: String,
}

impl From<&Diagnostic> for ErrorSummary {
    fn from(diagnostic: &Diagnostic) -> Self {
        ErrorSummary {
            file: display_path(&diagnostic.file),
            line: diagnostic.line(),
            column: diagnostic.column(),
            message: diagnostic.message.clone(),
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AssetSummary {
    pub name: String,
    pub kind: &'static str,
    pub status: AssetStatus,
    pub stages: Vec<StageSummary>,
    pub artifacts: Vec<ArtifactSummary>,
    pub errors: Vec<ErrorSummary>,
    /// What the asset's report warns about (UVs outside the map, an MTL map left out, a long
    /// bake); absent from the JSON when there is none.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<ErrorSummary>,
    /// The build record let the build pass it over: nothing it reads had moved (the text form
    /// counts such assets instead of listing them; the JSON lists them like any other).
    #[serde(skip)]
    pub passed_over: bool,
}

impl BuildSummary {
    pub fn all_ok(&self) -> bool {
        self.assets.iter().all(|asset| asset.status == AssetStatus::Ok)
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string(self).expect("summaries serialise")
    }

    /// A human-readable summary: one line per asset, its errors indented below; the assets the
    /// build passed over without warnings are counted on one line (a level has thousands).
    pub fn to_text(&self) -> String {
        let mut text = String::new();
        let quiet = |asset: &&AssetSummary| asset.passed_over && asset.warnings.is_empty();
        for asset in self.assets.iter().filter(|asset| !quiet(asset)) {
            let count = |status: StageStatus| asset.stages.iter().filter(|stage| stage.status == status).count();
            let ms = asset.stages.iter().fold(0.0, |total, stage| total + stage.ms);
            let status = match asset.status {
                AssetStatus::Ok => "ok",
                AssetStatus::Failed => "FAILED",
            };
            let remote = match count(StageStatus::Remote) {
                0 => String::new(),
                remote => format!(", {remote} from the shared cache"),
            };
            let _ = writeln!(
                text,
                "{status:<6} {} ({}): {} stages ran, {} cached{remote}, {} failed; {} artifacts; {ms:.0} ms of stage \
                    work",
                asset.name,
                asset.kind,
                count(StageStatus::Ran),
                count(StageStatus::Cached),
                count(StageStatus::Failed),
                asset.artifacts.len(),
            );
            for error in &asset.errors {
                let position = match (error.line, error.column) {
                    (Some(line), Some(column)) => format!(":{line}:{column}"),
                    (Some(line), None) => format!(":{line}"),
                    _ => String::new(),
                };
                let _ = writeln!(text, "       {}{position}: {}", error.file, error.message);
            }
            for warning in &asset.warnings {
                let position = warning.line.map(|line| format!(":{line}")).unwrap_or_default();
                let _ = writeln!(text, "       warning: {}{position}: {}", warning.file, warning.message);
            }
        }
        let unchanged = self.assets.iter().filter(quiet).count();
        if unchanged > 0 {
            let _ =
                writeln!(text, "ok     {unchanged} asset(s) unchanged: nothing they read moved since they were baked");
        }
        let _ = writeln!(text, "revision {}", self.revision);
        text
    }
}

/// A duration for people: `45 s`, `17 min`, `2.3 h`.
pub fn rough_duration(seconds: f64) -> String {
    match seconds {
        seconds if seconds < 90.0 => format!("{:.0} s", seconds.max(0.0)),
        seconds if seconds < 5400.0 => format!("{:.0} min", seconds / 60.0),
        seconds => format!("{:.1} h", seconds / 3600.0),
    }
}

/// What an artifact is, for an engine or a client choosing what to load (`role` in the manifest,
/// the protocol's `changed` entries and its `state` answer).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ArtifactRole {
    /// A block-compressed texture in its container (KTX2, DDS or PVR).
    Texture,
    /// A PNG of a surface: the preview of a texture, and what glTF and MTL files name.
    Image,
    /// An OBJ mesh.
    Mesh,
    /// An MTL file.
    Mtl,
    /// A glTF document (`.gltf`).
    Gltf,
    /// The binary buffer a glTF document names (`.bin`).
    GltfBuffer,
    /// A description in JSON an engine reads (an atlas's `atlas.json`, an impostor's
    /// `impostor.json`).
    Table,
    /// The asset's `report.json`.
    Report,
}
