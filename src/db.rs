//! The salsa glue, all of it: inputs (source files, assets, stage keys), the tracked stage
//! functions that call the pure stages, the persistent cache boundary, and the database with its
//! event log. Stages themselves live in their own modules and know nothing of salsa.

use std::collections::BTreeMap;
use std::fmt;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Instant;

use salsa::plumbing::AsId;

use crate::cache::{CacheEntry, CacheKey, CacheKeyBuilder, DiskCache};
use crate::config::{BlockFormat, Container, EncodeQuality, Settings};
use crate::diagnostic::Diagnostic;
use crate::kinds::material::channel_packing::pack_surface;
use crate::kinds::material::definition::{parse_material_file, MaterialConstants, MaterialFile};
use crate::texture::color::has_transparency;
use crate::texture::container::write_container;
use crate::texture::encode::{encode_levels, BlockEncodeSettings, EncodedTexture};
use crate::texture::mips::{mip_chain, mip_chain_reusing, MipSettings};
use crate::texture::preview::preview_png;
use crate::texture::SurfaceKind;
use crate::texture::{decode_texture, Texture};

/// The bytes of a source file and their blake3 hash. Equality is by hash.
#[derive(Clone)]
pub struct FileContents {
    pub bytes: Arc<[u8]>,
    pub hash: blake3::Hash,
}

impl FileContents {
    pub fn new(bytes: Vec<u8>) -> FileContents {
        let hash = blake3::hash(&bytes);
        FileContents { bytes: bytes.into(), hash }
    }
}

impl PartialEq for FileContents {
    fn eq(&self, other: &Self) -> bool {
        self.hash == other.hash
    }
}

impl Eq for FileContents {}

impl fmt::Debug for FileContents {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "FileContents({} bytes, {})", self.bytes.len(), &self.hash.to_hex()[..12])
    }
}

/// A file's contents, or why it could not be read.
pub type FileRead = Result<FileContents, String>;

/// A source file; `path` is relative to the folder of `pipeline.ron`.
/// Pipeline-wide limits, one per database (set by the driver from `pipeline.ron`).
#[salsa::input(singleton, debug)]
pub struct PipelineLimits {
    #[returns(copy)]
    pub texture: crate::texture::TextureLimits,
}

/// The texture limits in force (the defaults before the driver set any).
pub fn texture_limits(db: &dyn Db) -> crate::texture::TextureLimits {
    PipelineLimits::try_get(db).map_or_else(Default::default, |limits| limits.texture(db))
}

#[salsa::input(debug)]
pub struct SourceFile {
    #[returns(ref)]
    pub path: PathBuf,
    #[returns(ref)]
    pub contents: FileRead,
}

/// A `Material` asset: one `.mymaterial` file and the texture files it references.
#[salsa::input(debug)]
pub struct MaterialAsset {
    #[returns(ref)]
    pub name: String,
    /// The source folder (relative to the project) that texture paths must stay inside.
    #[returns(ref)]
    pub source_root: PathBuf,
    #[returns(copy)]
    pub file: SourceFile,
    #[returns(ref)]
    pub settings: Settings,
    /// Every texture the material file references, by project-relative path.
    #[returns(ref)]
    pub textures: Arc<BTreeMap<PathBuf, SourceFile>>,
}

/// One surface of one material of a `Material` asset: the key of the per-surface stages.
#[salsa::input(debug)]
pub struct SurfaceKey {
    #[returns(copy)]
    pub asset: MaterialAsset,
    #[returns(ref)]
    pub material: String,
    #[returns(copy)]
    pub surface: SurfaceKind,
}

/// The user-facing stages, in pipeline order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Stage {
    Parse,
    Decode,
    Pack,
    Mips,
    Encode,
    Write,
    Mesh,
    Planes,
    Layout,
    Render,
    Atlas,
    Lod,
}

impl Stage {
    pub const ALL: [Stage; 12] = [
        Stage::Parse,
        Stage::Decode,
        Stage::Pack,
        Stage::Mips,
        Stage::Encode,
        Stage::Write,
        Stage::Mesh,
        Stage::Planes,
        Stage::Layout,
        Stage::Render,
        Stage::Atlas,
        Stage::Lod,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Stage::Parse => "parse",
            Stage::Decode => "decode",
            Stage::Pack => "pack",
            Stage::Mips => "mips",
            Stage::Encode => "encode",
            Stage::Write => "write",
            Stage::Mesh => "mesh",
            Stage::Planes => "planes",
            Stage::Layout => "layout",
            Stage::Render => "render",
            Stage::Atlas => "atlas",
            Stage::Lod => "lod",
        }
    }

    /// The stage of a tracked function, by the function's name.
    pub fn of_function(function: &str) -> Option<Stage> {
        Some(match function {
            "material_file" => Stage::Parse,
            "decoded_texture" => Stage::Decode,
            "packed_surface" => Stage::Pack,
            "mip_levels" => Stage::Mips,
            "encoded_surface" => Stage::Encode,
            "surface_artifacts" => Stage::Write,
            "loaded_mesh" => Stage::Mesh,
            "billboard_planes" => Stage::Planes,
            "billboard_layout" => Stage::Layout,
            "plane_images" => Stage::Render,
            "billboard_atlas" => Stage::Atlas,
            "atlas_surface_artifacts" => Stage::Encode,
            "lod_files" => Stage::Lod,
            _ => return None,
        })
    }

    /// Bumped whenever the stage's output for the same inputs changes; part of cache keys.
    pub fn version(self) -> u32 {
        match self {
            // 2: opacity maps read alpha when the image has transparency.
            // 3: linear → sRGB bytes from tables, rounded like the f64 formula (was f32 powf).
            Stage::Pack => 3,
            // 2: coverage-preserving mips for albedo and opacity sources; opacity from alpha.
            // 3: transparent texels of albedo mips keep their footprint's colour (not black).
            // 4: sRGB bytes as Pack 3. 5: as Mips 4.
            Stage::Render => 5,
            // 2: transparent texels of albedo mips keep their footprint's colour (not black).
            // 3: sRGB bytes as Pack 3. 4: no coverage scaling when all or none of level 0 passes
            // the cutoff (alpha kept as it is, not scaled to just above the cutoff).
            Stage::Mips => 4,
            // 2: as Mips 2. 3: fully transparent BC7 blocks use the fastest profile. 4: as Mips 3.
            // 5: as Mips 4.
            Stage::Encode => 5,
            // 2: `map_d` naming the albedo texture is not applied a second time.
            Stage::Mesh => 2,
            // 2: each plane is fitted to its faces (least squares within ε), not left at the
            // edge of the valid offsets. 3: faces then move to their nearest plane holding their
            // material (rounds of reassignment and refitting).
            Stage::Planes => 3,
            // 2: faces of solid materials are also drawn on other planes' rectangles they lie
            // within ε of (crack filling).
            Stage::Layout => 2,
            _ => 1,
        }
    }
}

/// One execution of a stage body in this process.
#[derive(Clone, Debug, PartialEq)]
pub struct StageRun {
    pub stage: Stage,
    pub key: salsa::Id,
    pub ms: f64,
    /// The result came from the persistent cache; the stage itself did no work.
    pub from_cache: bool,
}

/// A tracked function that salsa executed (from its event log).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExecutedFunction {
    pub function: String,
    pub key: salsa::Id,
}

/// The last encoding of one atlas surface, so that an edit filters again only the mip tiles and
/// encodes again only the blocks it changed. A performance memory: results equal a full encode.
#[derive(Clone)]
pub struct PreviousEncoding {
    pub settings: BlockEncodeSettings,
    pub levels: Arc<Vec<Texture>>,
    pub mips: Option<Arc<crate::texture::mips::MipReuse>>,
    pub encoded: EncodedTexture,
    /// Level 0's squared error per block, for the PSNR.
    pub block_errors: Arc<crate::texture::quality::BlockErrors>,
}

type PreviousEncodings = Mutex<std::collections::HashMap<salsa::Id, PreviousEncoding>>;

#[derive(Default)]
struct Logs {
    executed: Mutex<Vec<ExecutedFunction>>,
    runs: Mutex<Vec<StageRun>>,
}

#[salsa::db]
pub trait Db: salsa::Database {
    fn disk_cache(&self) -> Option<&DiskCache>;
    fn record_run(&self, run: StageRun);
    fn previous_encoding(&self, key: salsa::Id) -> Option<PreviousEncoding>;
    fn remember_encoding(&self, key: salsa::Id, encoding: PreviousEncoding);
}

#[salsa::db]
#[derive(Clone)]
pub struct Database {
    storage: salsa::Storage<Self>,
    cache: Option<DiskCache>,
    logs: Arc<Logs>,
    encodings: Arc<PreviousEncodings>,
}

impl Database {
    pub fn new(cache: Option<DiskCache>) -> Database {
        let logs = Arc::new(Logs::default());
        let event_logs = logs.clone();
        let storage = salsa::Storage::new(Some(Box::new(move |event: salsa::Event| {
            if let salsa::EventKind::WillExecute { database_key } = event.kind {
                let text = format!("{database_key:?}");
                let function = text.split('(').next().unwrap_or_default().to_string();
                event_logs.executed.lock().expect("log lock").push(ExecutedFunction { function, key: database_key.key_index() });
            }
        })));
        Database { storage, cache, logs, encodings: Arc::default() }
    }

    /// The tracked functions salsa executed since the last call (its `WillExecute` events).
    pub fn take_executed(&self) -> Vec<ExecutedFunction> {
        std::mem::take(&mut *self.logs.executed.lock().expect("log lock"))
    }

    /// The stage bodies that ran since the last `take_runs`, leaving them logged.
    pub fn peek_runs(&self) -> Vec<StageRun> {
        self.logs.runs.lock().expect("log lock").clone()
    }

    /// The stage bodies that ran since the last call, with their durations.
    pub fn take_runs(&self) -> Vec<StageRun> {
        std::mem::take(&mut *self.logs.runs.lock().expect("log lock"))
    }
}

#[salsa::db]
impl salsa::Database for Database {}

#[salsa::db]
impl Db for Database {
    fn disk_cache(&self) -> Option<&DiskCache> {
        self.cache.as_ref()
    }

    fn record_run(&self, run: StageRun) {
        self.logs.runs.lock().expect("log lock").push(run);
    }

    fn previous_encoding(&self, key: salsa::Id) -> Option<PreviousEncoding> {
        self.encodings.lock().expect("encodings lock").get(&key).cloned()
    }

    fn remember_encoding(&self, key: salsa::Id, encoding: PreviousEncoding) {
        self.encodings.lock().expect("encodings lock").insert(key, encoding);
    }
}

/// Runs a stage body, timing it and recording the run.
fn timed<T>(db: &dyn Db, stage: Stage, key: impl AsId, body: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let result = body();
    db.record_run(StageRun { stage, key: key.as_id(), ms: start.elapsed().as_secs_f64() * 1000.0, from_cache: false });
    result
}

fn record_cache_hit(db: &dyn Db, stage: Stage, key: impl AsId) {
    db.record_run(StageRun { stage, key: key.as_id(), ms: 0.0, from_cache: true });
}

fn read_contents(db: &dyn Db, file: SourceFile) -> Result<&FileContents, Diagnostic> {
    file.contents(db).as_ref().map_err(|error| Diagnostic::new(file.path(db), error.clone()))
}

// ---------------------------------------------------------------------------------------------
// parse

/// The `.mymaterial` file of an asset, parsed (cached on disk by content).
#[salsa::tracked(returns(clone))]
pub fn material_file(db: &dyn Db, asset: MaterialAsset) -> Result<Arc<MaterialFile>, Diagnostic> {
    let file = asset.file(db);
    let contents = read_contents(db, file)?;
    let path = file.path(db);
    let source_root = asset.source_root(db);
    let key = CacheKeyBuilder::new("parse", Stage::Parse.version()).part(&contents.hash).part(path).part(source_root).finish();
    cached_json(db, Stage::Parse, asset, key, || timed(db, Stage::Parse, asset, || parse_material_file(path, &contents.bytes, source_root)))
        .map(Arc::new)
}

// ---------------------------------------------------------------------------------------------
// decode

/// A source texture as an opacity map (alpha if it has transparency, else red), decoded once.
#[salsa::tracked(returns(clone))]
pub fn opacity_texture(db: &dyn Db, file: SourceFile) -> Result<Arc<Texture>, Diagnostic> {
    let texture = decoded_texture(db, file)?;
    Ok(Arc::new(crate::texture::opacity_channel(&texture)))
}

/// A source texture decoded to RGBA8.
#[salsa::tracked(returns(clone))]
pub fn decoded_texture(db: &dyn Db, file: SourceFile) -> Result<Arc<Texture>, Diagnostic> {
    let contents = read_contents(db, file)?;
    let limits = texture_limits(db);
    timed(db, Stage::Decode, file, || decode_texture(file.path(db), &contents.bytes, limits).map(Arc::new))
}

// ---------------------------------------------------------------------------------------------
// per-surface inputs and settings (cheap; they exist so that unrelated edits cut off early)

/// What one surface is made of: its source files (one per slot) and constants.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceRecipe {
    pub material_file: PathBuf,
    /// One entry per slot of the surface; `None` where the material has no such map.
    pub sources: Vec<Option<SourceFile>>,
    pub constants: MaterialConstants,
}

#[salsa::tracked(returns(clone))]
pub fn surface_recipe(db: &dyn Db, key: SurfaceKey) -> Result<Arc<SurfaceRecipe>, Diagnostic> {
    let asset = key.asset(db);
    let parsed = material_file(db, asset)?;
    let material_path = asset.file(db).path(db).clone();
    let Some(material) = parsed.materials.iter().find(|material| &material.name == key.material(db)) else {
        return Err(Diagnostic::new(&material_path, format!("no material named `{}` any more", key.material(db))));
    };
    let textures = asset.textures(db);
    let mut sources = Vec::new();
    for slot in key.surface(db).slots() {
        let Some(reference) = material.textures.get(slot) else {
            sources.push(None);
            continue;
        };
        let Some(&file) = textures.get(&reference.path) else {
            return Err(Diagnostic::at(&material_path, reference.position, format!("texture \"{}\" was not read", reference.written)));
        };
        if let Err(error) = file.contents(db) {
            return Err(Diagnostic::at(
                &material_path,
                reference.position,
                format!(
                    "{} texture \"{}\" ({}): {error}",
                    slot.name(),
                    reference.written,
                    crate::diagnostic::display_path(&reference.path)
                ),
            ));
        }
        sources.push(Some(file));
    }
    Ok(Arc::new(SurfaceRecipe { material_file: material_path, sources, constants: material.constants.clone() }))
}

/// The settings that shape the mip chain of one surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MipStageSettings {
    pub mips: bool,
    /// The alpha-test cutoff, for albedo only.
    pub alpha_cutoff: Option<f32>,
}

#[salsa::tracked(returns(copy))]
pub fn mip_settings(db: &dyn Db, key: SurfaceKey) -> MipStageSettings {
    let settings = key.asset(db).settings(db);
    let alpha_cutoff = match (key.surface(db), surface_recipe(db, key)) {
        (SurfaceKind::Albedo, Ok(recipe)) => Some(recipe.constants.alpha_cutoff.unwrap_or(settings.billboard.alpha_cutoff)),
        _ => None,
    };
    MipStageSettings { mips: settings.encode.mips, alpha_cutoff }
}

#[salsa::tracked(returns(copy))]
pub fn block_settings(db: &dyn Db, key: SurfaceKey) -> (BlockFormat, EncodeQuality) {
    let encode = &key.asset(db).settings(db).encode;
    let format = match key.surface(db) {
        SurfaceKind::Albedo => encode.albedo,
        SurfaceKind::Mra => encode.mra,
        SurfaceKind::Normal => encode.normal,
        SurfaceKind::Height => encode.height,
    };
    (format, encode.quality)
}

#[salsa::tracked(returns(copy))]
pub fn file_settings(db: &dyn Db, key: SurfaceKey) -> (Container, Option<i32>) {
    let encode = &key.asset(db).settings(db).encode;
    (encode.container, encode.zstd)
}

// ---------------------------------------------------------------------------------------------
// pack, mips, encode, write

#[salsa::tracked(returns(clone))]
pub fn packed_surface(db: &dyn Db, key: SurfaceKey) -> Result<Arc<Texture>, Diagnostic> {
    let recipe = surface_recipe(db, key)?;
    let mut decoded = Vec::new();
    for source in &recipe.sources {
        decoded.push(match source {
            Some(file) => Some(decoded_texture(db, *file)?),
            None => None,
        });
    }
    timed(db, Stage::Pack, key, || {
        let sources: Vec<Option<&Texture>> = decoded.iter().map(|texture| texture.as_deref()).collect();
        Ok(Arc::new(pack_surface(key.surface(db), &sources, &recipe.constants)))
    })
}

/// The mip chain of a surface, and whether its alpha is tested (albedo with transparency).
#[derive(Clone, Debug, PartialEq)]
pub struct MipLevels {
    pub levels: Vec<Texture>,
    pub alpha_tested: bool,
}

#[salsa::tracked(returns(clone))]
pub fn mip_levels(db: &dyn Db, key: SurfaceKey) -> Result<Arc<MipLevels>, Diagnostic> {
    let packed = packed_surface(db, key)?;
    let settings = mip_settings(db, key);
    timed(db, Stage::Mips, key, || {
        let alpha_tested = key.surface(db) == SurfaceKind::Albedo && has_transparency(&packed);
        let levels = if settings.mips {
            let alpha_cutoff = if alpha_tested { settings.alpha_cutoff } else { None };
            mip_chain(&packed, MipSettings { kind: key.surface(db), alpha_cutoff })
        } else {
            vec![(*packed).clone()]
        };
        Ok(Arc::new(MipLevels { levels, alpha_tested }))
    })
}

/// A block-compressed surface and its measured quality.
#[derive(Clone, Debug, PartialEq)]
pub struct EncodedSurface {
    pub texture: EncodedTexture,
    /// PSNR of level 0 decoded against the uncompressed level 0, over the surface's channels.
    pub psnr_db: f64,
    pub alpha_tested: bool,
}

#[salsa::tracked(returns(clone))]
pub fn encoded_surface(db: &dyn Db, key: SurfaceKey) -> Result<Arc<EncodedSurface>, Diagnostic> {
    let mips = mip_levels(db, key)?;
    let (format, quality) = block_settings(db, key);
    let surface = key.surface(db);
    timed(db, Stage::Encode, key, || {
        let alpha = surface == SurfaceKind::Albedo && has_transparency(&mips.levels[0]);
        let settings = BlockEncodeSettings { format, quality, alpha, srgb: surface.is_srgb() };
        let texture = encode_levels(&mips.levels, settings);
        let level0 = &mips.levels[0];
        let errors = crate::texture::quality::block_errors_reusing(format, &texture.levels[0], level0, surface.channels(), None);
        let psnr_db = errors.psnr(level0.width, level0.height);
        Ok(Arc::new(EncodedSurface { texture, psnr_db, alpha_tested: mips.alpha_tested }))
    })
}

/// What one surface is written as, with the figures its report needs.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SurfaceInfo {
    pub surface: SurfaceKind,
    pub format: BlockFormat,
    pub srgb: bool,
    pub container: Container,
    pub width: u32,
    pub height: u32,
    pub levels: u32,
    pub bytes: u64,
    pub psnr_db: f64,
    pub alpha_tested: bool,
}

/// The files of one surface: the texture container and a PNG preview of the packed surface.
#[derive(Clone, Debug, PartialEq)]
pub struct SurfaceArtifacts {
    pub info: SurfaceInfo,
    pub texture_file: Arc<[u8]>,
    pub preview_png: Arc<[u8]>,
}

/// The artifacts of a surface: from the persistent cache when its inputs were baked before.
#[salsa::tracked(returns(clone))]
pub fn surface_artifacts(db: &dyn Db, key: SurfaceKey) -> Result<Arc<SurfaceArtifacts>, Diagnostic> {
    let recipe = surface_recipe(db, key)?;
    let mip_settings = mip_settings(db, key);
    let block_settings = block_settings(db, key);
    let file_settings = file_settings(db, key);
    let mut cache_key = CacheKeyBuilder::new("surface", 1)
        .part(&[Stage::Pack, Stage::Mips, Stage::Encode, Stage::Write].map(Stage::version))
        .part(&key.surface(db))
        .part(&recipe.constants)
        .part(&mip_settings.mips)
        .part(&mip_settings.alpha_cutoff)
        .part(&block_settings)
        .part(&file_settings);
    for source in &recipe.sources {
        cache_key = match source {
            Some(file) => cache_key.part(&read_contents(db, *file)?.hash),
            None => cache_key.part("none"),
        };
    }
    let cache_key = cache_key.finish();
    if let Some(artifacts) = load_cached(db, "surface", cache_key, artifacts_from_entry) {
        record_cache_hit(db, Stage::Write, key);
        return Ok(Arc::new(artifacts));
    }
    let encoded = encoded_surface(db, key)?;
    let packed = packed_surface(db, key)?;
    let artifacts = timed(db, Stage::Write, key, || {
        let (container, zstd) = file_settings;
        let texture_file: Arc<[u8]> = write_container(&encoded.texture, container, zstd).into();
        let info = SurfaceInfo {
            surface: key.surface(db),
            format: encoded.texture.format,
            srgb: encoded.texture.srgb,
            container,
            width: encoded.texture.width,
            height: encoded.texture.height,
            levels: encoded.texture.levels.len() as u32,
            bytes: texture_file.len() as u64,
            psnr_db: (encoded.psnr_db * 100.0).round() / 100.0,
            alpha_tested: encoded.alpha_tested,
        };
        SurfaceArtifacts { info, texture_file, preview_png: preview_png(&packed).into() }
    });
    store_cached(db, "surface", cache_key, || CacheEntry {
        metadata: serde_json::to_value(&artifacts.info).expect("surface info serialises"),
        blobs: vec![artifacts.texture_file.to_vec(), artifacts.preview_png.to_vec()],
    });
    Ok(Arc::new(artifacts))
}

fn artifacts_from_entry(entry: CacheEntry) -> Option<SurfaceArtifacts> {
    let info = serde_json::from_value(entry.metadata).ok()?;
    let [texture_file, preview_png]: [Vec<u8>; 2] = entry.blobs.try_into().ok()?;
    Some(SurfaceArtifacts { info, texture_file: texture_file.into(), preview_png: preview_png.into() })
}

fn load_cached<T>(db: &dyn Db, stage: &str, key: CacheKey, decode: impl FnOnce(CacheEntry) -> Option<T>) -> Option<T> {
    db.disk_cache()?.load(stage, key).and_then(decode)
}

fn store_cached(db: &dyn Db, stage: &str, key: CacheKey, entry: impl FnOnce() -> CacheEntry) {
    if let Some(cache) = db.disk_cache() {
        cache.store(stage, key, &entry());
    }
}

/// A stage result stored as JSON metadata under the stage's name (parsed materials, plane sets,
/// layouts: small, exact with `float_roundtrip`): loaded (a cache hit of `stage` for `id`), or
/// computed and stored.
fn cached_json<T: serde::Serialize + serde::de::DeserializeOwned>(
    db: &dyn Db,
    stage: Stage,
    id: impl AsId,
    key: CacheKey,
    compute: impl FnOnce() -> Result<T, Diagnostic>,
) -> Result<T, Diagnostic> {
    if let Some(value) = load_cached(db, stage.name(), key, |entry| serde_json::from_value::<T>(entry.metadata).ok()) {
        record_cache_hit(db, stage, id);
        return Ok(value);
    }
    let value = compute()?;
    store_cached(db, stage.name(), key, || CacheEntry {
        metadata: serde_json::to_value(&value).expect("stage results serialise"),
        blobs: Vec::new(),
    });
    Ok(value)
}

/// Plain values as raw bytes, for cache blobs (little-endian on every machine cirrus runs on).
fn pod_blob<T: bytemuck::Pod>(values: &[T]) -> Vec<u8> {
    bytemuck::cast_slice(values).to_vec()
}

fn from_pod_blob<T: bytemuck::Pod>(bytes: &[u8]) -> Option<Vec<T>> {
    bytes.len().is_multiple_of(std::mem::size_of::<T>()).then(|| bytemuck::pod_collect_to_vec(bytes))
}

// ---------------------------------------------------------------------------------------------
// billboard clouds: mesh → planes → layout → per-plane renders → atlas → encoded surfaces, LOD
//
// The mesh, planes, layout, LOD and each atlas surface's encode are also kept in the persistent
// cache, under keys chained from the keys of what they read (mesh inputs → planes → layout → LOD;
// each atlas surface by its content), so that after a restart a texture edit re-runs the renders
// and the atlas, and encodes only the surfaces whose texels changed.

/// A `BillboardCloud` asset: an OBJ, the MTL files it names and the textures they name.
#[salsa::input(debug)]
pub struct BillboardAsset {
    #[returns(ref)]
    pub name: String,
    #[returns(ref)]
    pub source_root: PathBuf,
    #[returns(copy)]
    pub mesh_file: SourceFile,
    #[returns(ref)]
    pub libraries: Arc<BTreeMap<PathBuf, SourceFile>>,
    #[returns(ref)]
    pub textures: Arc<BTreeMap<PathBuf, SourceFile>>,
    #[returns(ref)]
    pub settings: Settings,
    /// One key per plane, set by the driver once the layout is known.
    #[returns(ref)]
    pub plane_keys: Arc<Vec<PlaneKey>>,
}

/// One plane of a billboard cloud: the key of its render stage.
#[salsa::input(debug)]
pub struct PlaneKey {
    #[returns(copy)]
    pub asset: BillboardAsset,
    #[returns(copy)]
    pub index: u32,
}

/// One atlas surface of a billboard cloud: the key of its encode stage.
#[salsa::input(debug)]
pub struct AtlasSurfaceKey {
    #[returns(copy)]
    pub asset: BillboardAsset,
    #[returns(copy)]
    pub surface: SurfaceKind,
}

fn library_bytes(db: &dyn Db, asset: BillboardAsset) -> BTreeMap<PathBuf, Option<Vec<u8>>> {
    asset
        .libraries(db)
        .iter()
        .map(|(path, file)| (path.clone(), file.contents(db).as_ref().ok().map(|contents| contents.bytes.to_vec())))
        .collect()
}

/// The texture files the mesh's materials name (cheap: the MTL files only).
#[salsa::tracked(returns(clone))]
pub fn mesh_textures(db: &dyn Db, asset: BillboardAsset) -> Arc<Vec<PathBuf>> {
    Arc::new(crate::mesh::texture_paths(asset.mesh_file(db).path(db), &library_bytes(db, asset), asset.source_root(db)))
}

/// A loaded mesh with its vertex tangents and load warnings.
#[derive(Debug, PartialEq)]
pub struct LoadedMesh {
    pub mesh: crate::mesh::Mesh,
    pub tangents: Vec<[f32; 4]>,
    pub warnings: Vec<Diagnostic>,
}

/// The content address of what the mesh stage reads: the OBJ and its MTL files (paths and
/// bytes), and the source folder texture paths must stay in.
#[salsa::tracked(returns(copy))]
pub fn mesh_cache_key(db: &dyn Db, asset: BillboardAsset) -> CacheKey {
    let key = CacheKeyBuilder::new("mesh", Stage::Mesh.version()).part(asset.source_root(db));
    let files = std::iter::once(asset.mesh_file(db)).chain(asset.libraries(db).values().copied());
    key_with_files(db, key, files).finish()
}

/// Adds each file's path and its content hash (or why it could not be read) to a key.
fn key_with_files(db: &dyn Db, key: CacheKeyBuilder, files: impl IntoIterator<Item = SourceFile>) -> CacheKeyBuilder {
    files.into_iter().fold(key, |key, file| {
        let key = key.part(file.path(db));
        match file.contents(db) {
            Ok(contents) => key.part(&contents.hash),
            Err(error) => key.part(error),
        }
    })
}

fn loaded_mesh_entry(loaded: &LoadedMesh) -> CacheEntry {
    let mesh = &loaded.mesh;
    CacheEntry {
        metadata: serde_json::json!({ "materials": mesh.materials, "warnings": loaded.warnings, "uvs": mesh.uvs.is_some() }),
        blobs: vec![
            pod_blob(&mesh.positions),
            pod_blob(&mesh.normals),
            mesh.uvs.as_deref().map(pod_blob).unwrap_or_default(),
            pod_blob(&mesh.triangles),
            pod_blob(&mesh.triangle_materials),
            pod_blob(&loaded.tangents),
        ],
    }
}

fn loaded_mesh_from_entry(entry: CacheEntry) -> Option<LoadedMesh> {
    let [positions, normals, uvs, triangles, triangle_materials, tangents]: [Vec<u8>; 6] = entry.blobs.try_into().ok()?;
    let mesh = crate::mesh::Mesh {
        positions: from_pod_blob(&positions)?,
        normals: from_pod_blob(&normals)?,
        uvs: if entry.metadata.get("uvs")?.as_bool()? { Some(from_pod_blob(&uvs)?) } else { None },
        triangles: from_pod_blob(&triangles)?,
        triangle_materials: from_pod_blob(&triangle_materials)?,
        materials: serde_json::from_value(entry.metadata.get("materials")?.clone()).ok()?,
    };
    let warnings = serde_json::from_value(entry.metadata.get("warnings")?.clone()).ok()?;
    Some(LoadedMesh { mesh, tangents: from_pod_blob(&tangents)?, warnings })
}

#[salsa::tracked(returns(clone))]
pub fn loaded_mesh(db: &dyn Db, asset: BillboardAsset) -> Result<Arc<LoadedMesh>, Diagnostic> {
    let file = asset.mesh_file(db);
    let contents = read_contents(db, file)?;
    // A missing MTL is a warning (its materials fall back to defaults); one that is there but
    // cannot be read (not a regular file, no permission) fails the mesh, naming why.
    for (path, library) in asset.libraries(db).iter() {
        if let Err(why) = library.contents(db) {
            if why != crate::sources::FILE_NOT_FOUND {
                return Err(Diagnostic::new(path, why.clone()));
            }
        }
    }
    let cache_key = mesh_cache_key(db, asset);
    if let Some(loaded) = load_cached(db, "mesh", cache_key, loaded_mesh_from_entry) {
        record_cache_hit(db, Stage::Mesh, asset);
        return Ok(Arc::new(loaded));
    }
    let libraries = library_bytes(db, asset);
    let loaded = timed(db, Stage::Mesh, asset, || {
        let (mesh, warnings) = crate::mesh::load_mesh(file.path(db), &contents.bytes, &libraries, asset.source_root(db))?;
        let tangents = match &mesh.uvs {
            Some(uvs) => crate::mesh::vertex_tangents(&mesh.positions, &mesh.normals, uvs, &mesh.triangles),
            None => Vec::new(),
        };
        Ok(LoadedMesh { mesh, tangents, warnings })
    })?;
    store_cached(db, "mesh", cache_key, || loaded_mesh_entry(&loaded));
    Ok(Arc::new(loaded))
}

#[salsa::tracked(returns(copy))]
pub fn plane_settings(db: &dyn Db, asset: BillboardAsset) -> crate::kinds::billboard_cloud::planes::PlaneSettings {
    let billboard = &asset.settings(db).billboard;
    crate::kinds::billboard_cloud::planes::PlaneSettings { epsilon: billboard.epsilon, max_planes: billboard.max_planes }
}

#[salsa::tracked(returns(copy))]
pub fn planes_cache_key(db: &dyn Db, asset: BillboardAsset) -> CacheKey {
    let settings = plane_settings(db, asset);
    CacheKeyBuilder::new("planes", Stage::Planes.version())
        .part(&mesh_cache_key(db, asset).0)
        .part(&settings.epsilon)
        .part(&settings.max_planes)
        .finish()
}

#[salsa::tracked(returns(clone))]
pub fn billboard_planes(db: &dyn Db, asset: BillboardAsset) -> Result<Arc<crate::kinds::billboard_cloud::planes::PlaneSet>, Diagnostic> {
    cached_json(db, Stage::Planes, asset, planes_cache_key(db, asset), || {
        let loaded = loaded_mesh(db, asset)?;
        let settings = plane_settings(db, asset);
        timed(db, Stage::Planes, asset, || {
            Ok(crate::kinds::billboard_cloud::planes::select_planes(
                &loaded.mesh.positions,
                &loaded.mesh.triangles,
                &loaded.mesh.triangle_materials,
                settings,
            ))
        })
    })
    .map(Arc::new)
}

/// The planes' rectangles and their atlas layout.
#[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BillboardLayout {
    pub rectangles: Vec<crate::kinds::billboard_cloud::rectangles::PlaneRectangle>,
    pub layout: crate::kinds::billboard_cloud::layout::Layout,
    /// The render stages: each plane's rectangles grouped by the materials they show.
    pub render_groups: Vec<crate::kinds::billboard_cloud::render_groups::RenderGroup>,
}

#[salsa::tracked(returns(clone))]
pub fn atlas_layout_settings(db: &dyn Db, asset: BillboardAsset) -> (crate::config::AtlasSettings, Option<f32>) {
    let settings = asset.settings(db);
    (settings.atlas.clone(), settings.billboard.texel_density)
}

#[salsa::tracked(returns(copy))]
pub fn layout_cache_key(db: &dyn Db, asset: BillboardAsset) -> CacheKey {
    let (atlas, density) = atlas_layout_settings(db, asset);
    CacheKeyBuilder::new("layout", Stage::Layout.version()).part(&planes_cache_key(db, asset).0).part(&atlas).part(&density).finish()
}

#[salsa::tracked(returns(clone))]
pub fn billboard_layout(db: &dyn Db, asset: BillboardAsset) -> Result<Arc<BillboardLayout>, Diagnostic> {
    cached_json(db, Stage::Layout, asset, layout_cache_key(db, asset), || compute_billboard_layout(db, asset)).map(Arc::new)
}

fn compute_billboard_layout(db: &dyn Db, asset: BillboardAsset) -> Result<BillboardLayout, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let planes = billboard_planes(db, asset)?;
    let (atlas, density) = atlas_layout_settings(db, asset);
    timed(db, Stage::Layout, asset, || {
        let mut rectangles =
            crate::kinds::billboard_cloud::rectangles::plane_rectangles(&loaded.mesh.positions, &loaded.mesh.triangles, &planes);
        let solid_materials: Vec<bool> = loaded.mesh.materials.iter().map(|material| !material.cut_out).collect();
        let crack_filling = crate::kinds::billboard_cloud::rectangles::CrackFillingInput {
            positions: &loaded.mesh.positions,
            triangles: &loaded.mesh.triangles,
            face_materials: &loaded.mesh.triangle_materials,
            solid_materials: &solid_materials,
        };
        crate::kinds::billboard_cloud::rectangles::add_crack_filling_faces(&crack_filling, &planes, &mut rectangles);
        let sizes: Vec<(f32, f32)> = rectangles.iter().map(|rectangle| (rectangle.width, rectangle.height)).collect();
        let layout = crate::kinds::billboard_cloud::layout::layout_rectangles(&sizes, &atlas, density);
        let render_groups = crate::kinds::billboard_cloud::render_groups::render_groups(&loaded.mesh, &rectangles);
        Ok(BillboardLayout { rectangles, layout, render_groups })
    })
}

/// `lod.obj` and `lod.mtl`: planes and layout only, so texture edits leave them alone.
#[salsa::tracked(returns(clone))]
pub fn lod_files(db: &dyn Db, asset: BillboardAsset) -> Result<Arc<(String, String)>, Diagnostic> {
    let key = CacheKeyBuilder::new("lod", Stage::Lod.version()).part(&layout_cache_key(db, asset).0).finish();
    cached_json(db, Stage::Lod, asset, key, || {
        let layout = billboard_layout(db, asset)?;
        timed(db, Stage::Lod, asset, || {
            Ok(crate::kinds::billboard_cloud::lod_mesh::lod_mesh(&layout.rectangles, &layout.layout, "billboard_cloud"))
        })
    })
    .map(Arc::new)
}

#[salsa::tracked(returns(copy))]
pub fn billboard_alpha_cutoff(db: &dyn Db, asset: BillboardAsset) -> f32 {
    asset.settings(db).billboard.alpha_cutoff
}

/// The images of one render group (four per rectangle, in rectangle order): one plane's
/// rectangles that show the same materials, rendered on the GPU in one go; reads only the
/// textures of those materials.
#[salsa::tracked(returns(clone))]
pub fn plane_images(db: &dyn Db, key: PlaneKey) -> Result<Arc<Vec<crate::gpu::PlaneImages>>, Diagnostic> {
    let asset = key.asset(db);
    let loaded = loaded_mesh(db, asset)?;
    let layout = billboard_layout(db, asset)?;
    let alpha_cutoff = billboard_alpha_cutoff(db, asset);
    let index = key.index(db) as usize;
    let mesh_path = asset.mesh_file(db).path(db).clone();
    let Some(group) = layout.render_groups.get(index) else {
        return Err(Diagnostic::new(&mesh_path, format!("render group {index} no longer exists")));
    };
    // Plane images stay out of the persistent cache: on the oak they are 40 MB in 1,245 entries,
    // and storing them made a full bake 1.0 s slower (3.2 → 4.2 s on ext4), more than rendering
    // every group again after a restart costs (0.8 s wall).
    let planes = billboard_planes(db, asset)?;
    let rectangles: Vec<(&crate::packing::Placement, &crate::kinds::billboard_cloud::rectangles::PlaneRectangle)> = group
        .rectangles
        .iter()
        .map(|&rectangle| (&layout.layout.placements[rectangle as usize], &layout.rectangles[rectangle as usize]))
        .collect();
    let mut materials = vec![crate::gpu::RenderMaterial::default(); loaded.mesh.materials.len()];
    let with_uvs = loaded.mesh.uvs.is_some();
    for &material_index in &group.materials {
        let source = &loaded.mesh.materials[material_index as usize];
        let decoded = |slot: crate::texture::TextureSlot| -> Result<Option<Arc<Texture>>, Diagnostic> {
            let Some(path) = source.maps.get(&slot).filter(|_| with_uvs) else { return Ok(None) };
            let Some(&file) = asset.textures(db).get(path) else {
                return Err(Diagnostic::new(&mesh_path, format!("texture {} was not read", crate::diagnostic::display_path(path))));
            };
            if let Err(error) = file.contents(db) {
                return Err(Diagnostic::new(
                    &mesh_path,
                    format!("material `{}`: {} texture {}: {error}", source.name, slot.name(), crate::diagnostic::display_path(path)),
                ));
            }
            if slot == crate::texture::TextureSlot::Opacity { opacity_texture(db, file) } else { decoded_texture(db, file) }.map(Some)
        };
        use crate::texture::TextureSlot;
        materials[material_index as usize] = crate::gpu::RenderMaterial {
            albedo: decoded(TextureSlot::Albedo)?,
            opacity: decoded(TextureSlot::Opacity)?,
            normal: decoded(TextureSlot::Normal)?,
            metallic: decoded(TextureSlot::Metallic)?,
            roughness: decoded(TextureSlot::Roughness)?,
            ao: decoded(TextureSlot::Ao)?,
            albedo_factor: [source.albedo_factor[0], source.albedo_factor[1], source.albedo_factor[2], source.opacity],
            metallic_value: source.metallic,
            roughness_value: source.roughness,
            ao_value: 1.0,
        };
    }
    // The depth range covers every assigned face, also beyond ε when `max_planes` capped them.
    let depth_range = planes.epsilon.max(planes.max_error).max(1e-6);
    timed(db, Stage::Render, key, || {
        let gpu = crate::gpu::gpu().map_err(|error| Diagnostic::new(&mesh_path, error.to_string()))?;
        let inputs: Vec<crate::gpu::PlaneRenderInput> = rectangles
            .iter()
            .map(|(placement, rectangle)| crate::gpu::PlaneRenderInput {
                frame: rectangle.frame(),
                epsilon: depth_range,
                alpha_cutoff,
                width: placement.width,
                height: placement.height,
                batches: crate::kinds::billboard_cloud::render_groups::plane_batches(&loaded.mesh, &loaded.tangents, rectangle),
                materials: &materials,
            })
            .collect();
        gpu.render_rectangles(&inputs).map_err(|error| Diagnostic::new(&mesh_path, error.to_string()))
    })
    .map(Arc::new)
}

/// Every render group's images of `asset`, in render-group order.
fn render_group_images(db: &dyn Db, asset: BillboardAsset) -> Result<Vec<Arc<Vec<crate::gpu::PlaneImages>>>, Diagnostic> {
    asset.plane_keys(db).iter().map(|key| plane_images(db, *key)).collect()
}

/// The images of every rectangle, in layout order: each group's images belong to its
/// rectangles, and every rectangle is in one group.
fn images_by_rectangle<'a>(layout: &BillboardLayout, images: &'a [Arc<Vec<crate::gpu::PlaneImages>>]) -> Vec<&'a crate::gpu::PlaneImages> {
    let mut by_rectangle: Vec<Option<&crate::gpu::PlaneImages>> = vec![None; layout.rectangles.len()];
    for (group, group_images) in layout.render_groups.iter().zip(images) {
        for (&rectangle, image) in group.rectangles.iter().zip(group_images.iter()) {
            by_rectangle[rectangle as usize] = Some(image);
        }
    }
    by_rectangle.into_iter().map(|image| image.expect("every rectangle is in a render group")).collect()
}

/// The atlas texels that faces cover (part of the atlas stage): unchanged by colour-only
/// edits, which therefore skip the fill search below.
#[salsa::tracked(returns(clone))]
pub fn atlas_coverage(db: &dyn Db, asset: BillboardAsset) -> Result<Arc<crate::kinds::billboard_cloud::atlas::AtlasCoverage>, Diagnostic> {
    let layout = billboard_layout(db, asset)?;
    let images = render_group_images(db, asset)?;
    timed(db, Stage::Atlas, asset, || {
        Ok(Arc::new(crate::kinds::billboard_cloud::atlas::atlas_coverage(&layout.layout, &images_by_rectangle(&layout, &images))))
    })
}

/// Where each atlas texel takes its values from, uncovered ones by the fill search (part of the
/// atlas stage).
#[salsa::tracked(returns(clone))]
pub fn atlas_texel_sources(
    db: &dyn Db,
    asset: BillboardAsset,
) -> Result<Arc<crate::kinds::billboard_cloud::atlas::TexelSources>, Diagnostic> {
    let coverage = atlas_coverage(db, asset)?;
    timed(db, Stage::Atlas, asset, || Ok(Arc::new(crate::kinds::billboard_cloud::atlas::texel_sources(&coverage))))
}

#[salsa::tracked(returns(clone))]
pub fn billboard_atlas(db: &dyn Db, asset: BillboardAsset) -> Result<Arc<crate::kinds::billboard_cloud::atlas::AtlasImages>, Diagnostic> {
    let layout = billboard_layout(db, asset)?;
    let images = render_group_images(db, asset)?;
    let coverage = atlas_coverage(db, asset)?;
    let sources = atlas_texel_sources(db, asset)?;
    timed(db, Stage::Atlas, asset, || {
        Ok(Arc::new(crate::kinds::billboard_cloud::atlas::composite_atlas(
            &layout.layout,
            &images_by_rectangle(&layout, &images),
            &coverage,
            &sources,
        )))
    })
}

/// One surface of the atlas (cheap; cuts off when only other surfaces changed).
#[salsa::tracked(returns(clone))]
pub fn atlas_surface(db: &dyn Db, key: AtlasSurfaceKey) -> Result<Arc<Texture>, Diagnostic> {
    let atlas = billboard_atlas(db, key.asset(db))?;
    Ok(Arc::new(match key.surface(db) {
        SurfaceKind::Albedo => atlas.albedo.clone(),
        SurfaceKind::Mra => atlas.mra.clone(),
        SurfaceKind::Normal => atlas.normal.clone(),
        SurfaceKind::Height => atlas.height.clone(),
    }))
}

#[salsa::tracked(returns(clone))]
pub fn atlas_block_settings(db: &dyn Db, key: AtlasSurfaceKey) -> (BlockFormat, EncodeQuality, bool, Container, Option<i32>, f32) {
    let settings = key.asset(db).settings(db);
    let encode = &settings.encode;
    let format = match key.surface(db) {
        SurfaceKind::Albedo => encode.albedo,
        SurfaceKind::Mra => encode.mra,
        SurfaceKind::Normal => encode.normal,
        SurfaceKind::Height => encode.height,
    };
    (format, encode.quality, encode.mips, encode.container, encode.zstd, settings.billboard.alpha_cutoff)
}

/// Mips, block compression (with its measured PSNR), container and preview of one atlas surface.
#[salsa::tracked(returns(clone))]
pub fn atlas_surface_artifacts(db: &dyn Db, key: AtlasSurfaceKey) -> Result<Arc<SurfaceArtifacts>, Diagnostic> {
    let image = atlas_surface(db, key)?;
    let (format, quality, mips, container, zstd, alpha_cutoff) = atlas_block_settings(db, key);
    let surface = key.surface(db);
    let cache_key = CacheKeyBuilder::new("atlas-surface", 1)
        .part(&[Stage::Mips, Stage::Encode, Stage::Write].map(Stage::version))
        .part(&surface)
        .part(&image.width)
        .part(&image.height)
        .part(&image.hash)
        .part(&(format, quality))
        .part(&mips)
        .part(&(container, zstd))
        .part(&alpha_cutoff)
        .finish();
    if let Some(artifacts) = load_cached(db, "atlas-surface", cache_key, artifacts_from_entry) {
        record_cache_hit(db, Stage::Encode, key);
        return Ok(Arc::new(artifacts));
    }
    let artifacts = encode_atlas_surface(db, key, &image)?;
    store_cached(db, "atlas-surface", cache_key, || CacheEntry {
        metadata: serde_json::to_value(&artifacts.info).expect("surface info serialises"),
        blobs: vec![artifacts.texture_file.to_vec(), artifacts.preview_png.to_vec()],
    });
    Ok(artifacts)
}

/// Mips, blocks (reusing the last encoding's unchanged tiles and blocks), PSNR, container and
/// preview of one atlas surface.
fn encode_atlas_surface(db: &dyn Db, key: AtlasSurfaceKey, image: &Texture) -> Result<Arc<SurfaceArtifacts>, Diagnostic> {
    let (format, quality, mips, container, zstd, alpha_cutoff) = atlas_block_settings(db, key);
    let surface = key.surface(db);
    timed(db, Stage::Encode, key, || {
        let alpha_tested = surface == SurfaceKind::Albedo && has_transparency(image);
        let previous = db.previous_encoding(key.as_id());
        let (levels, mip_reuse) = if mips {
            let previous_mips = previous.as_ref().and_then(|previous| Some((previous.levels.as_slice(), &**previous.mips.as_ref()?)));
            mip_chain_reusing(image, MipSettings { kind: surface, alpha_cutoff: alpha_tested.then_some(alpha_cutoff) }, previous_mips)
        } else {
            (vec![image.clone()], None)
        };
        let settings = BlockEncodeSettings { format, quality, alpha: alpha_tested, srgb: surface.is_srgb() };
        let previous_blocks = previous.as_ref().filter(|previous| previous.settings == settings);
        let texture = crate::texture::encode::encode_levels_reusing(
            &levels,
            settings,
            previous_blocks.map(|previous| (previous.levels.as_slice(), &previous.encoded)),
        );
        let block_errors = crate::texture::quality::block_errors_reusing(
            format,
            &texture.levels[0],
            image,
            surface.channels(),
            previous_blocks.map(|previous| (&previous.levels[0], &previous.encoded.levels[0][..], &*previous.block_errors)),
        );
        let psnr_db = (block_errors.psnr(image.width, image.height) * 100.0).round() / 100.0;
        let levels = Arc::new(levels);
        db.remember_encoding(
            key.as_id(),
            PreviousEncoding {
                settings,
                levels: levels.clone(),
                mips: mip_reuse.map(Arc::new),
                encoded: texture.clone(),
                block_errors: Arc::new(block_errors),
            },
        );
        let texture_file: Arc<[u8]> = write_container(&texture, container, zstd).into();
        let info = SurfaceInfo {
            surface,
            format,
            srgb: surface.is_srgb(),
            container,
            width: image.width,
            height: image.height,
            levels: levels.len() as u32,
            bytes: texture_file.len() as u64,
            psnr_db,
            alpha_tested,
        };
        Ok(Arc::new(SurfaceArtifacts { info, texture_file, preview_png: preview_png(image).into() }))
    })
}

/// The content address of a billboard cloud's artifacts: every input file and setting.
#[salsa::tracked(returns(copy))]
pub fn billboard_cache_key(db: &dyn Db, asset: BillboardAsset) -> CacheKey {
    let settings = asset.settings(db);
    // 2: render stages are per plane and material set, listed in the entry's metadata.
    let key = CacheKeyBuilder::new("billboard", 2)
        .part(&[Stage::Mesh, Stage::Planes, Stage::Layout, Stage::Render, Stage::Atlas, Stage::Encode, Stage::Lod].map(Stage::version))
        .part(&settings.billboard)
        .part(&settings.atlas)
        .part(&settings.encode)
        .part(asset.source_root(db));
    let files =
        std::iter::once(asset.mesh_file(db)).chain(asset.libraries(db).values().copied()).chain(asset.textures(db).values().copied());
    key_with_files(db, key, files).finish()
}
