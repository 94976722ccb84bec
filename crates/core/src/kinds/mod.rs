//! The asset kinds as the machinery sees them: the questions the driver asks each of them
//! (`Kind`), the table of a kind's answers its `AssetKind` holds (`KindQuestions`), and what the
//! answers are made of: jobs to run on workers, stage instances (the build summary, the graph dump
//! and the event-log labels all come from them) and outputs. Adding a kind: a crate under `kinds/`
//! with a `Kind` implementation, its `KIND` and its settings (its `pipeline.ron` entry,
//! `config::KindEntry`), and one line in the application's list (see ARCHITECTURE.md).

use std::path::{Path, PathBuf};
use std::sync::Arc;

pub use crate::config::AssetKind;
use crate::config::{AssetConfig, PipelineConfig};
use crate::db::{Asset, Db, Stage, StageRun};
use crate::diagnostic::Diagnostic;
use crate::texture::tail::TailSettings;
use crate::texture::SurfaceKind;
pub use surface::{SurfaceFn, SurfaceId, SurfacePart, SurfacePlan};

pub mod tail_queries;
pub mod mesh_queries;
pub mod source_copies;
pub mod checks;
pub mod surface;

/// The questions the driver asks an asset kind. Every answer is computed from the database
/// (through the kind's tracked functions); none does IO but `preview`, which `cirrus preview`
/// asks after a build (it reads the baked files and writes its sheets).
pub trait Kind {
    /// The files the asset reads, as far as the files read so far tell (the driver reads them
    /// and asks again until nothing new turns up).
    fn files_to_read(db: &dyn Db, asset: Asset) -> Vec<PathBuf>;

    /// The first jobs of a build; each job may schedule more.
    fn first_jobs(db: &dyn Db, asset: Asset) -> Vec<Job>;

    /// The kind's own steps: what its jobs do besides running surfaces through the tail.
    type Step: KindStep;

    /// Runs one of the kind's own steps (surfaces are run by the shared tail).
    fn run_step(db: &dyn Db, asset: Asset, step: &Self::Step) -> Result<Vec<Job>, Diagnostic>;

    /// Every stage instance of the asset, as far as known, marked failed where `errors` left it
    /// without a result.
    fn stage_instances(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &[Diagnostic]) -> Vec<StageInstance>;

    /// The files to write (project-relative paths inside `output_folder`) and the report, from
    /// the finished stages; `runs` are this build's stage runs (for timings in the report).
    fn outputs(
        db: &dyn Db,
        asset: Asset,
        output_folder: &Path,
        errors: &mut Vec<Diagnostic>,
        runs: &[StageRun],
    ) -> AssetOutputs;

    /// `cirrus check`: the asset's sources validated without baking.
    fn check(config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic>;

    /// What the tail needs of one of the asset's surfaces: its settings, the surface that cuts
    /// it out, and the functions that name its recipe and parts and make its image.
    fn surface_plan(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<SurfacePlan, Diagnostic>;

    /// The stage whose result is the image of `surface`, for another asset that reads the
    /// surface as a source (a `Material`'s `ao_source`): none when this kind makes no such
    /// surface, an error when it would but cannot (no such group, a broken source).
    /// `surface.group` may be the group's name or its folder.
    fn provided_surface_stage(_db: &dyn Db, _asset: Asset, _surface: &SurfaceId) -> Result<Option<Read>, Diagnostic> {
        Ok(None)
    }

    /// `cirrus preview` of the built asset: renders what it baked beside its source, writes the
    /// contact sheets and metrics under `options.out` and says what it compared. A kind that
    /// bakes no mesh has nothing to preview.
    fn preview(
        db: &dyn Db,
        asset: Asset,
        _config: &PipelineConfig,
        _options: &PreviewOptions,
    ) -> Result<PreviewReport, PreviewError> {
        Err(PreviewError::NotPreviewable { name: asset.name(db).clone(), kind: asset.kind(db).name() })
    }

    /// Bounds the kind's own memos of large values (images it makes for the tail) to the
    /// `surfaces` surfaces used last, as `tail_queries::keep_memos` bounds the tail's (0:
    /// unbounded). The driver sets it from its memory budget; a kind whose memos are small keeps
    /// the default, which bounds nothing.
    fn keep_memos(_db: &mut dyn Db, _surfaces: usize) {}

    /// The bytes the asset's bake holds for the images it makes itself, beyond its source images
    /// (a billboard cloud's renders and atlases, an AO or height map and what baking it takes),
    /// estimated from its settings alone: what the driver's memory budget counts for the asset
    /// besides its sources. A kind that makes no images of its own, or only small ones, keeps
    /// the default, none.
    fn made_bytes(_db: &dyn Db, _asset: Asset) -> u64 {
        0
    }
}

/// What `cirrus preview` renders, and where.
#[derive(Clone, Debug)]
pub struct PreviewOptions {
    pub asset: String,
    pub settings: crate::preview::PreviewSettings,
    /// Where the sheets and metrics go (project-relative or absolute).
    pub out: PathBuf,
    /// A billboard cloud's chain: only this level (none: every level).
    pub lod: Option<u32>,
    /// A billboard cloud: what stands for each level beside the source, the baked LOD or the
    /// source's faces moved onto the level's planes.
    pub stand_in: StandIn,
}

/// One comparison of a preview: what stood beside the source (a LOD level, a remapped mesh;
/// none for an asset's only LOD), its figures, and the folder of its `contact_sheet.png` and
/// `metrics.json`.
#[derive(Clone, Debug)]
pub struct PreviewRow {
    pub label: Option<String>,
    pub metrics: crate::preview::PreviewMetrics,
    pub folder: PathBuf,
}

/// What `cirrus preview` compared, and the sheet of every comparison side by side when it made
/// several of one source (a LOD chain).
#[derive(Clone, Debug)]
pub struct PreviewReport {
    pub rows: Vec<PreviewRow>,
    pub chain_sheet: Option<PathBuf>,
}

#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    #[error(
        "asset `{name}` is a {kind}: it bakes no mesh to preview (BillboardCloud and Atlas assets with `meshes` do)"
    )]
    NotPreviewable { name: String, kind: &'static str },
    #[error("asset `{name}` has no LOD level {level}: it has {levels} (0 to {})", levels - 1)]
    NoSuchLevel { name: String, level: u32, levels: u32 },
    /// An option the asset's kind does not take.
    #[error("{0}")]
    Option(String),
    #[error("{0}")]
    Artifact(Diagnostic),
    #[error(transparent)]
    Gpu(#[from] crate::gpu::GpuError),
    #[error("cannot write the preview: {0}")]
    Write(std::io::Error),
}

/// The OBJ at `obj` with the MTL files and maps it names, read from `files` as an engine reads
/// them (each map decoded once), its cut-out materials alpha-tested at
/// `alpha_cutoff`; paths must stay inside `source_root`. An atlas's remapped meshes and their
/// sources, a billboard chain's reduced levels.
pub fn mesh_view_from_files(
    files: &BakedFiles,
    obj: &Path,
    (source_root, limits): (&Path, crate::texture::TextureLimits),
    (alpha_cutoff, maps): (f32, MapFiles),
) -> Result<crate::gpu::ViewMesh, Diagnostic> {
    let read = |path: &Path| files.read(path);
    let bytes = read(obj)?;
    let libraries: std::collections::BTreeMap<PathBuf, Option<Vec<u8>>> =
        crate::mesh::material_libraries(obj, &bytes, source_root)
            .into_iter()
            .map(|path| {
                let bytes = read(&path).ok();
                (path, bytes)
            })
            .collect();
    let (mesh, _) = crate::mesh::load_mesh(obj, &bytes, &libraries, source_root)?;
    let uvs = mesh.uvs.as_deref().unwrap_or(&[]);
    let tangents = crate::mesh::vertex_tangents(&mesh.positions, &mesh.normals, uvs, &mesh.triangles);
    // Each file decoded once (a page is a material's albedo and opacity, and several materials').
    let decoded: std::cell::RefCell<std::collections::BTreeMap<PathBuf, Arc<crate::texture::Texture>>> =
        Default::default();
    crate::preview::mesh_view(&mesh, &tangents, alpha_cutoff, |material, slot| {
        let Some(path) = material.maps.get(&slot).filter(|_| mesh.uvs.is_some()) else { return Ok(None) };
        let known = decoded.borrow().get(path).cloned();
        let texture = match (known, maps.twin(files, path)) {
            (Some(texture), _) => texture,
            (None, Some(twin)) => {
                let levels = crate::texture::quality::decoded_container_levels(&twin, &read(&twin)?)?;
                Arc::new(levels.into_iter().next().ok_or_else(|| Diagnostic::new(&twin, "a texture without levels"))?)
            }
            (None, None) => Arc::new(crate::texture::decode_texture(path, &read(path)?, limits)?),
        };
        decoded.borrow_mut().insert(path.clone(), texture.clone());
        Ok(Some(match slot {
            crate::texture::TextureSlot::Opacity => Arc::new(crate::texture::opacity_channel(&texture)),
            _ => texture,
        }))
    })
}

/// Which file [`mesh_view_from_files`] reads a map from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapFiles {
    /// The file the MTL names.
    AsNamed,
    /// The block-compressed twin the tail wrote beside a PNG it names (`albedo.ktx2`, `.dds` or
    /// `.pvr` beside `albedo.png`), BC-decoded: what an engine that loads the KTX2 draws. The
    /// PNG where there is none.
    BlockCompressedTwins,
}

impl MapFiles {
    /// The twin of the map at `path` in `files` that this reads instead of it.
    fn twin(self, files: &BakedFiles, path: &Path) -> Option<PathBuf> {
        if self == MapFiles::AsNamed || path.extension().is_none_or(|extension| extension != "png") {
            return None;
        }
        let twins = ["ktx2", "dds", "pvr"].map(|extension| path.with_extension(extension));
        twins.into_iter().find(|twin| files.exists(twin))
    }
}

/// Writes one comparison's `contact_sheet.png` and `metrics.json` into `folder`.
pub fn write_preview(folder: &Path, preview: &crate::preview::Preview) -> Result<(), PreviewError> {
    let mut metrics = serde_json::to_vec_pretty(&preview.metrics).expect("metrics serialise");
    metrics.push(b'\n');
    let write = |name: &str, bytes: &[u8]| crate::files::write_if_changed(&folder.join(name), bytes);
    write("contact_sheet.png", &preview.contact_sheet)
        .and_then(|_| write("metrics.json", &metrics))
        .map_err(PreviewError::Write)?;
    Ok(())
}

impl PreviewError {
    /// Whether the command was asked wrongly (rather than the asset failing to preview).
    pub fn is_usage(&self) -> bool {
        matches!(self, PreviewError::NotPreviewable { .. } | PreviewError::NoSuchLevel { .. } | PreviewError::Option(_))
    }
}

/// What the scheduler asks of a kind's step, and the kind that runs it.
pub trait KindStep: Clone + std::fmt::Debug + PartialEq + Send + Sync + 'static {
    /// The kind whose `run_step` runs it.
    type Kind: Kind<Step = Self>;

    /// The sort of work it is, for estimating how long the waiting jobs take (the steps of one
    /// sort take about as long as each other).
    fn sort(&self) -> &'static str;
}

/// A step of some kind's own (its `Kind::Step`), as a job carries it: the kind's type erased, so
/// that the driver and the scheduler name no kind's steps (the kind runs its own).
#[derive(Clone)]
pub struct Step(Arc<dyn AnyStep>);

/// A kind's step behind [`Step`].
trait AnyStep: std::fmt::Debug + Send + Sync {
    fn sort(&self) -> &'static str;
    fn run(&self, db: &dyn Db, asset: Asset) -> Result<Vec<Job>, Diagnostic>;
    /// Whether `other` is a step of the same kind, equal to this one.
    fn same(&self, other: &dyn std::any::Any) -> bool;
    fn as_any(&self) -> &dyn std::any::Any;
}

impl<S: KindStep> AnyStep for S {
    fn sort(&self) -> &'static str {
        KindStep::sort(self)
    }

    fn run(&self, db: &dyn Db, asset: Asset) -> Result<Vec<Job>, Diagnostic> {
        S::Kind::run_step(db, asset, self)
    }

    fn same(&self, other: &dyn std::any::Any) -> bool {
        other.downcast_ref::<S>().is_some_and(|other| other == self)
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

impl Step {
    fn sort(&self) -> &'static str {
        self.0.sort()
    }
}

impl<S: KindStep> From<S> for Step {
    fn from(step: S) -> Step {
        Step(Arc::new(step))
    }
}

impl PartialEq for Step {
    /// Steps of one kind compare as that kind's; steps of two kinds differ.
    fn eq(&self, other: &Step) -> bool {
        self.0.same(other.0.as_any())
    }
}

impl std::fmt::Debug for Step {
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(formatter)
    }
}

/// Runs a job on a worker: a surface through the shared tail, a step by its kind.
pub fn run_job(db: &dyn Db, job: &Job) -> Result<Vec<Job>, Diagnostic> {
    match &job.task {
        Task::Surface(surface) => tail_queries::surface_artifacts(db, job.asset, surface.clone()).map(|_| Vec::new()),
        Task::LoadPreviousEncoding(surface) => {
            tail_queries::load_previous_encoding(db, job.asset, surface);
            Ok(Vec::new())
        }
        Task::Step(step) => step.0.run(db, job.asset),
    }
}

/// The questions of [`Kind`] as one kind answers them: what its [`AssetKind`] holds (made by
/// its folder, `KIND`), so that the driver asks any kind without naming it.
pub struct KindQuestions {
    files_to_read: fn(&dyn Db, Asset) -> Vec<PathBuf>,
    first_jobs: fn(&dyn Db, Asset) -> Vec<Job>,
    stage_instances: fn(&dyn Db, Asset, &Path, &[Diagnostic]) -> Vec<StageInstance>,
    outputs: OutputsFn,
    check: fn(&PipelineConfig, &AssetConfig) -> Vec<Diagnostic>,
    surface_plan: fn(&dyn Db, Asset, &SurfaceId) -> Result<SurfacePlan, Diagnostic>,
    provided_surface_stage: ProvidedSurfaceFn,
    preview: fn(&dyn Db, Asset, &PipelineConfig, &PreviewOptions) -> Result<PreviewReport, PreviewError>,
    keep_memos: fn(&mut dyn Db, usize),
    made_bytes: fn(&dyn Db, Asset) -> u64,
}

/// [`Kind::outputs`].
type OutputsFn = fn(&dyn Db, Asset, &Path, &mut Vec<Diagnostic>, &[StageRun]) -> AssetOutputs;
/// [`Kind::provided_surface_stage`].
type ProvidedSurfaceFn = fn(&dyn Db, Asset, &SurfaceId) -> Result<Option<Read>, Diagnostic>;

impl KindQuestions {
    /// Kind `K`'s answers.
    pub const fn of<K: Kind>() -> KindQuestions {
        KindQuestions {
            files_to_read: K::files_to_read,
            first_jobs: K::first_jobs,
            stage_instances: K::stage_instances,
            outputs: K::outputs,
            check: K::check,
            surface_plan: K::surface_plan,
            provided_surface_stage: K::provided_surface_stage,
            preview: K::preview,
            keep_memos: K::keep_memos,
            made_bytes: K::made_bytes,
        }
    }
}

/// Each question of [`Kind`], asked of whichever kind this is.
impl AssetKind {
    fn answers(self) -> &'static KindQuestions {
        self.questions().downcast_ref().expect("a kind's questions are its KindQuestions")
    }

    pub fn files_to_read(self, db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
        (self.answers().files_to_read)(db, asset)
    }

    pub fn first_jobs(self, db: &dyn Db, asset: Asset) -> Vec<Job> {
        (self.answers().first_jobs)(db, asset)
    }

    pub fn stage_instances(
        self,
        db: &dyn Db,
        asset: Asset,
        output_folder: &Path,
        errors: &[Diagnostic],
    ) -> Vec<StageInstance> {
        (self.answers().stage_instances)(db, asset, output_folder, errors)
    }

    pub fn outputs(
        self,
        db: &dyn Db,
        asset: Asset,
        output_folder: &Path,
        errors: &mut Vec<Diagnostic>,
        runs: &[StageRun],
    ) -> AssetOutputs {
        (self.answers().outputs)(db, asset, output_folder, errors, runs)
    }

    pub fn check(self, config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic> {
        (self.answers().check)(config, asset)
    }

    pub fn surface_plan(self, db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<SurfacePlan, Diagnostic> {
        (self.answers().surface_plan)(db, asset, surface)
    }

    pub fn preview(
        self,
        db: &dyn Db,
        asset: Asset,
        config: &PipelineConfig,
        options: &PreviewOptions,
    ) -> Result<PreviewReport, PreviewError> {
        (self.answers().preview)(db, asset, config, options)
    }

    pub fn keep_memos(self, db: &mut dyn Db, surfaces: usize) {
        (self.answers().keep_memos)(db, surfaces)
    }

    pub fn made_bytes(self, db: &dyn Db, asset: Asset) -> u64 {
        (self.answers().made_bytes)(db, asset)
    }

    pub fn provided_surface_stage(
        self,
        db: &dyn Db,
        asset: Asset,
        surface: &SurfaceId,
    ) -> Result<Option<Read>, Diagnostic> {
        (self.answers().provided_surface_stage)(db, asset, surface)
    }
}

/// Work for a worker thread: one step of an asset, or one surface through the tail.
pub type Job = crate::schedule::Job<Task>;

impl crate::schedule::JobTask for Task {
    /// A step's name, or `surface`.
    fn sort(&self) -> &'static str {
        match self {
            Task::Step(step) => step.sort(),
            Task::Surface(_) => "surface",
            Task::LoadPreviousEncoding(_) => "previous-encoding",
        }
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum Task {
    /// A step of the kind's own.
    Step(Step),
    /// A surface through the shared texture tail.
    Surface(SurfaceId),
    /// Loads a surface's last encoding from the persistent cache ahead of its tail (a kind
    /// schedules it beside slower work, so that the load is off the surface's path).
    LoadPreviousEncoding(SurfaceId),
}

impl Task {
    /// A job's task of one of the kind's own steps.
    pub fn step(step: impl Into<Step>) -> Task {
        Task::Step(step.into())
    }
}

/// One instance of a stage, as the summary, the graph dump and the event log name it.
#[derive(Clone, Debug, PartialEq)]
pub struct StageInstance {
    pub stage: Stage,
    /// Its label in the event log and the graph: the node is `stage(label)`.
    pub label: String,
    /// Its name in the build summary (inside the asset).
    pub instance: String,
    /// What its function reads.
    pub reads: Vec<Read>,
    /// The artifacts made from its result (project-relative).
    pub writes: Vec<PathBuf>,
    /// Shared by every asset that reads the same file (a decode), not owned by this asset.
    pub shared: bool,
    /// The asset's errors left it without a result.
    pub failed: bool,
}

/// One read of a stage instance: a source file, or another instance's result.
#[derive(Clone, Debug, PartialEq)]
pub enum Read {
    File(PathBuf),
    Stage(Stage, String),
}

impl StageInstance {
    pub fn new(stage: Stage, label: impl Into<String>, instance: impl Into<String>) -> StageInstance {
        StageInstance {
            stage,
            label: label.into(),
            instance: instance.into(),
            reads: Vec::new(),
            writes: Vec::new(),
            shared: false,
            failed: false,
        }
    }

    pub fn reads_stage(mut self, other: &StageInstance) -> Self {
        self.reads.push(Read::Stage(other.stage, other.label.clone()));
        self
    }

    /// The node id in the graph and the event log: `stage(label)`.
    pub fn node_id(&self) -> String {
        stage_node_id(self.stage.name, &self.label)
    }
}

/// The graph id of a stage instance, as the event log names it: `stage(label)`.
pub fn stage_node_id(stage: &str, label: &str) -> String {
    format!("{stage}({label})")
}

/// The shared tail stages of one surface (mips → encode → write), reading `image` (the stage
/// that made the surface's image) and writing its two files.
pub fn tail_instances(
    asset_name: &str,
    surface: &SurfaceId,
    image: &StageInstance,
    files: &[PathBuf],
) -> [StageInstance; 3] {
    let label = surface.label(asset_name);
    let instance = surface.instance();
    let mips = StageInstance::new(tail_queries::MIPS, &label, &instance).reads_stage(image);
    let encode = StageInstance::new(tail_queries::ENCODE, &label, &instance).reads_stage(&mips);
    let mut write = StageInstance::new(tail_queries::WRITE, &label, &instance).reads_stage(&encode).reads_stage(image);
    write.writes = files.to_vec();
    [mips, encode, write]
}

/// The tail settings of a surface of kind `surface` in `format`, the rest from the asset's
/// `encode` settings.
pub fn tail_settings_from(
    encode: &crate::config::EncodeSettings,
    surface: SurfaceKind,
    format: crate::config::BlockFormat,
    alpha_cutoff: Option<f32>,
) -> TailSettings {
    TailSettings {
        surface,
        format,
        quality: encode.quality,
        mips: encode.mips,
        alpha_cutoff,
        container: encode.container,
        zstd: encode.zstd,
        packing: encode.packing,
    }
}

/// An asset's outputs made by `make` when its stages left no error; the error of making them
/// joins `errors` (and nothing is written).
pub fn outputs_unless_failed(
    errors: &mut Vec<Diagnostic>,
    make: impl FnOnce() -> Result<AssetOutputs, Diagnostic>,
) -> AssetOutputs {
    if !errors.is_empty() {
        return AssetOutputs::default();
    }
    make().unwrap_or_else(|diagnostic| {
        errors.push(diagnostic);
        AssetOutputs::default()
    })
}

/// What an asset writes: files (project-relative) and its `report.json`, written last.
#[derive(Clone, Debug, Default)]
pub struct AssetOutputs {
    pub files: Vec<(PathBuf, crate::summary::ArtifactRole, Arc<[u8]>)>,
    pub report: Option<Vec<u8>>,
    /// What some files' values mean (a height map's `center` and `magnitude`), listed beside
    /// them in the manifest.
    pub meanings: std::collections::BTreeMap<PathBuf, serde_json::Value>,
    /// What the report warns about, for the build summary too.
    pub warnings: Vec<crate::summary::ErrorSummary>,
}

impl AssetOutputs {
    /// Adds a file the asset writes, and what it is.
    pub fn add(&mut self, path: PathBuf, role: crate::summary::ArtifactRole, bytes: Arc<[u8]>) {
        self.files.push((path, role, bytes));
    }
}

/// Where baked files are read from: the project on disk (paths relative to its root), or a
/// build's outputs before they are written (paths as the kind added them).
pub enum BakedFiles<'a> {
    Disk(&'a Path),
    Outputs(&'a AssetOutputs),
}

impl BakedFiles<'_> {
    /// The bytes of `path`.
    pub fn read(&self, path: &Path) -> Result<Vec<u8>, Diagnostic> {
        match self {
            BakedFiles::Disk(root) => crate::files::read_regular_file(&root.join(path), crate::files::MAX_SOURCE_BYTES)
                .map_err(|error| Diagnostic::new(path, format!("cannot read: {error}"))),
            BakedFiles::Outputs(outputs) => outputs
                .files
                .iter()
                .find(|(written, _, _)| written == path)
                .map(|(_, _, bytes)| bytes.to_vec())
                .ok_or_else(|| Diagnostic::new(path, "the build writes no such file")),
        }
    }

    /// Whether `path` is a file there.
    pub fn exists(&self, path: &Path) -> bool {
        match self {
            BakedFiles::Disk(root) => root.join(path).is_file(),
            BakedFiles::Outputs(outputs) => outputs.files.iter().any(|(written, _, _)| written == path),
        }
    }
}

/// Milliseconds each stage of an asset spent in this build (runs labelled by the asset's name
/// or below it, cache hits left out), for its report.
pub fn asset_stage_ms<'a>(asset_name: &str, runs: &'a [StageRun]) -> std::collections::BTreeMap<&'a str, f64> {
    let mut stage_ms = std::collections::BTreeMap::new();
    let below = format!("{asset_name}/");
    for run in runs.iter().filter(|run| !run.from_cache && (run.label == asset_name || run.label.starts_with(&below))) {
        *stage_ms.entry(run.stage).or_insert(0.0) += run.ms;
    }
    // Rounded once, after summing, so that the report reads 59.4 and not 59.400000000000006.
    for ms in stage_ms.values_mut() {
        *ms = (*ms * 10.0).round() / 10.0;
    }
    stage_ms
}

/// What a preview compares with the source: the baked LOD, or a stand-in that keeps some of the
/// cloud's losses and not others. A stand-in is the source's own faces, drawn with the source's
/// textures at full resolution (no atlas, no mips, no block compression), each moved onto the
/// plane the cloud draws it on; so the baked LOD against `Projected` is what the atlas costs,
/// `Projected` against `Translated` what foreshortening costs, and `Translated` what displacement
/// alone costs, which no texture can win back.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StandIn {
    /// The baked `lod.obj` with its decoded atlas.
    #[default]
    Baked,
    /// Every corner of a face at its orthogonal projection on the face's plane: the cloud's
    /// geometry.
    Projected,
    /// Every face moved along its plane's normal by its corners' mean distance from the plane:
    /// displaced as the cloud displaces it on average, keeping its shape and orientation.
    Translated,
}

impl StandIn {
    pub const ALL: [StandIn; 3] = [StandIn::Baked, StandIn::Projected, StandIn::Translated];

    pub fn name(self) -> &'static str {
        match self {
            StandIn::Baked => "baked",
            StandIn::Projected => "projected",
            StandIn::Translated => "translated",
        }
    }
}
