//! The Material kind's tracked functions: thin glue between the database and the kind's pure
//! stages (parse, channel packing); the surfaces then run through the shared texture tail.

use std::path::PathBuf;
use std::sync::Arc;

use super::definition::{parse_material_file, MaterialConstants, MaterialFile};
use crate::cache::{CacheKey, CacheKeyBuilder, KeyPart};
use crate::db::{cached_json, decoded_for_surface, read_contents, stage_key, timed, Asset, Db, SourceFile, Stage};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::{Read, SurfaceId};
use crate::settings::Settings as Own;
use crate::texture::channel_packing::pack_surface;
use crate::texture::{SurfaceKind, Texture, TextureSlot};

pub(crate) const PARSE: Stage = Stage { name: "parse", version: 1 };
// 2: opacity maps read alpha when the image has transparency. 3: linear → sRGB bytes from
// tables, rounded like the f64 formula (was f32 powf).
pub(crate) const PACK: Stage = Stage { name: "pack", version: 3 };

impl KeyPart for MaterialConstants {
    fn add_to(&self, key: CacheKeyBuilder) -> CacheKeyBuilder {
        let MaterialConstants { albedo, metallic, roughness, ao, alpha_cutoff } = self;
        key.part(albedo).part(metallic).part(roughness).part(ao).part(alpha_cutoff)
    }
}

/// The input of the `.mymaterial` file (cuts off when textures join or leave the asset).
fn material_source(db: &dyn Db, asset: Asset) -> Result<SourceFile, Diagnostic> {
    let path = asset.main_file(db);
    crate::db::asset_file(db, asset, path.clone()).ok_or_else(|| Diagnostic::new(path, "was not read"))
}

/// The `.mymaterial` file of an asset, parsed (cached on disk by content).
#[salsa::tracked(returns(clone))]
pub(crate) fn material_file(db: &dyn Db, asset: Asset) -> Result<Arc<MaterialFile>, Diagnostic> {
    let file = material_source(db, asset)?;
    let contents = read_contents(db, file)?;
    let path = file.path(db);
    let source_root = asset.source_root(db);
    let key = stage_key(PARSE).part(&contents.hash).part(&crate::db::source_relative(db, path)).finish();
    let label = display_path(path);
    cached_json(db, PARSE, &label, key, || {
        timed(db, PARSE, &label, || parse_material_file(path, &contents.bytes()?, source_root))
    })
    .map(Arc::new)
}

/// What one surface is made of: its sources (one per slot) and constants.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SurfaceRecipe {
    /// One entry per slot of the surface; `None` where the material has no such map.
    pub sources: Vec<Option<MapSource>>,
    pub constants: MaterialConstants,
}

/// Where one slot's map comes from.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum MapSource {
    /// A texture file the material names.
    File(SourceFile),
    /// Another asset's surface: the `ao_source` asset's AO map of the material's name, made
    /// by `stage`.
    Asset { asset: Asset, name: String, surface: SurfaceId, stage: Read },
}

/// An error of the `ao_source` asset `name`, as the reading asset reports it.
fn from_ao_source(db: &dyn Db, asset: Asset, name: &str, error: Diagnostic) -> Diagnostic {
    Diagnostic { message: format!("ao_source `{name}` of `{}`: {}", asset.name(db), error.message), ..error }
}

/// The AO map of `material` from the asset's `ao_source`, if it names one.
fn ao_source_map(db: &dyn Db, asset: Asset, material: &str) -> Result<Option<MapSource>, Diagnostic> {
    let Some(name) = &asset.settings(db).own::<Own>().ao_source else { return Ok(None) };
    let reader = asset.main_file(db);
    let Some(source) = crate::db::asset_named(db, name) else {
        return Err(Diagnostic::new(reader, format!("ao_source `{name}` names no asset of the pipeline")));
    };
    let surface = SurfaceId::new(material, SurfaceKind::Ao);
    match source
        .kind(db)
        .provided_surface_stage(db, source, &surface)
        .map_err(|error| from_ao_source(db, asset, name, error))?
    {
        Some(stage) => Ok(Some(MapSource::Asset { asset: source, name: name.clone(), surface, stage })),
        None => Err(Diagnostic::new(reader, format!("ao_source `{name}` is not an AmbientOcclusion asset"))),
    }
}

#[salsa::tracked(returns(clone))]
pub(crate) fn surface_recipe(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<SurfaceRecipe>, Diagnostic> {
    let parsed = material_file(db, asset)?;
    let material_path = asset.main_file(db);
    let Some(material) = parsed.materials.iter().find(|material| material.name == surface.group) else {
        return Err(Diagnostic::new(material_path, format!("no material named `{}` any more", surface.group)));
    };
    let mut sources = Vec::new();
    for slot in surface.surface.slots() {
        if *slot == TextureSlot::Ao {
            if let Some(map) = ao_source_map(db, asset, &material.name)? {
                sources.push(Some(map));
                continue;
            }
        }
        let Some(reference) = material.textures.get(slot) else {
            sources.push(None);
            continue;
        };
        let Some(file) = crate::db::asset_file(db, asset, reference.path.clone()) else {
            return Err(Diagnostic::at(
                material_path,
                reference.position,
                format!("texture \"{}\" was not read", reference.written),
            ));
        };
        if let Err(error) = file.contents(db) {
            return Err(Diagnostic::at(
                material_path,
                reference.position,
                format!(
                    "{} texture \"{}\" ({}): {error}",
                    slot.name(),
                    reference.written,
                    display_path(&reference.path)
                ),
            ));
        }
        sources.push(Some(MapSource::File(file)));
    }
    Ok(Arc::new(SurfaceRecipe { sources, constants: material.constants.clone() }))
}

/// Bounds the packed surfaces kept to the `surfaces` used last (see `Kind::keep_memos`).
pub(crate) fn keep_memos(db: &mut dyn Db, surfaces: usize) {
    packed_surface::set_lru_capacity(db, surfaces);
}

/// The surface packed from its source maps (stage `pack`).
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn packed_surface(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
    pack(db, asset, &surface)
}

/// The surface packed from its source maps, for a tail that keeps it (through
/// [`packed_surface`]) or uses it once (see `db::Retention`).
pub(crate) fn surface_for_tail(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
    match db.retention(asset) {
        crate::db::Retention::KeepForNextBuild => packed_surface(db, asset, surface.clone()),
        crate::db::Retention::OutputsOnly => pack(db, asset, surface),
    }
}

fn pack(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
    let recipe = surface_recipe(db, asset, surface.clone())?;
    let mut decoded: Vec<Option<Arc<Texture>>> = Vec::new();
    for (slot, source) in recipe.sources.iter().enumerate() {
        let earlier_slot_of = |file: &SourceFile| {
            let same = |earlier: &Option<MapSource>| matches!(earlier, Some(MapSource::File(seen)) if seen == file);
            recipe.sources[..slot].iter().position(same)
        };
        decoded.push(match source {
            // A file in several slots (an ORM map) is decoded once.
            Some(MapSource::File(file)) => match earlier_slot_of(file) {
                Some(earlier) => decoded[earlier].clone(),
                None => Some(decoded_for_surface(db, asset, *file)?),
            },
            Some(MapSource::Asset { asset: source, name, surface, .. }) => {
                let plan = crate::kinds::tail_queries::surface_plan(db, *source, surface.clone());
                let image = plan.and_then(|plan| (plan.image)(db, *source, surface));
                Some(image.map_err(|error| from_ao_source(db, asset, name, error))?)
            }
            None => None,
        });
    }
    timed(db, PACK, &surface.label(asset.name(db)), || {
        let sources: Vec<Option<&Texture>> = decoded.iter().map(|texture| texture.as_deref()).collect();
        Ok(Arc::new(pack_surface(surface.surface, &sources, &recipe.constants.pack_constants())))
    })
}

/// What a surface's image is made of: the pack stage's version, the constants and each slot's
/// source content.
#[salsa::tracked(returns(clone))]
pub(crate) fn surface_recipe_key(db: &dyn Db, asset: Asset, surface: SurfaceId) -> Result<CacheKey, Diagnostic> {
    let recipe = surface_recipe(db, asset, surface.clone())?;
    let mut key = stage_key(PACK).part(&surface.surface).part(&recipe.constants);
    for source in &recipe.sources {
        key = match source {
            Some(MapSource::File(file)) => key.part(&read_contents(db, *file)?.hash),
            Some(MapSource::Asset { asset: source, surface, .. }) => {
                let plan = crate::kinds::tail_queries::surface_plan(db, *source, surface.clone())?;
                match (plan.recipe)(db, *source, surface)? {
                    Some(recipe) => key.part("asset").part(&recipe.0),
                    // No cheap key: what the image holds.
                    None => key.part("image").part(&(plan.image)(db, *source, surface)?.hash),
                }
            }
            None => key.part("none"),
        };
    }
    Ok(key.finish())
}

/// Every texture the material file references (project-relative), once each.
pub(crate) fn referenced_textures(parsed: &MaterialFile) -> Vec<PathBuf> {
    let mut paths: Vec<PathBuf> = parsed
        .materials
        .iter()
        .flat_map(|material| material.textures.values())
        .map(|reference| reference.path.clone())
        .collect();
    paths.sort();
    paths.dedup();
    paths
}
