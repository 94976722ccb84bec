//! The BillboardCloud kind's tracked functions: thin glue between the database and the kind's
//! pure stages (mesh → planes → layout → per-group renders → atlas, and the LOD mesh). Render
//! groups are tracked functions of (asset, group index); the atlas surfaces go through the
//! shared texture tail.
//!
//! The mesh, planes, layout and LOD are also kept in the persistent cache, under keys chained
//! from the keys of what they read (mesh inputs → planes → layout → LOD), so that after a
//! restart a texture edit re-runs only the renders, the atlas and the surfaces whose texels
//! changed.

use std::collections::{BTreeMap, HashMap};
use std::path::PathBuf;
use std::sync::Arc;

use crate::kinds::mesh_queries::LoadedMesh;
use crate::mesh::gltf::GltfFiles;

use super::layout::Layout;
use super::rectangles::PlaneRectangle;
use super::render_groups::RenderGroup;
use crate::cache::{CacheEntry, CacheKey, CacheKeyBuilder};
use crate::db::{
    asset_file, cached_json, decoded_texture, from_pod_blob, key_with_files, load_cached, opacity_texture, pod_blob,
    record_cache_hit, stage_key, store_cached_in_background, timed, timed_together, Asset, Db, SourceFile, Stage,
};
use crate::diagnostic::{display_path, Diagnostic};
use crate::gpu::PlaneImages;
use crate::kinds::mesh_queries::{loaded_mesh, mesh_cache_key, mesh_textures};
use crate::settings::Settings as Own;
use crate::texture::{SurfaceKind, Texture, TextureSlot};

// Planes 2: each plane is fitted to its faces (least squares within ε). 3: faces then move to
// their nearest plane holding their material (rounds of reassignment and refitting). 5: a
// budget's planes are refined as k-planes and filled up to the budget; the mean error.
pub(crate) const PLANES: Stage = Stage { name: "planes", version: 6 };
// Layout 2: faces of solid materials are also drawn on other planes' rectangles they lie within
// ε of (crack filling).
// 4: the density fills the atlas as far as the packer can (bisection after the 5 % steps).
// 5: crack filling only next to the other plane's faces.
pub(crate) const LAYOUT: Stage = Stage { name: "layout", version: 5 };
// Render 2–5: coverage-preserving mips of alpha sources; transparent texels keep their
// footprint's colour; sRGB bytes from tables; no coverage scaling when all or none pass.
// 6: distance-field alpha from 2 × 2 samples; 7: colours shaded once per texel, coverage alone
// at 2 × 2 samples.
pub(crate) const RENDER: Stage = Stage { name: "render", version: 7 };
pub(crate) const ATLAS: Stage = Stage { name: "atlas", version: 1 };
/// 2: the OBJ alone (the MTL is written with the asset's packing).
pub const LOD: Stage = Stage { name: "lod", version: 2 };
/// A reduced level (`mesh::reduce`: meshoptimizer, cards thinned whole). 2: the OBJ's header
/// names no asset (assets with the same mesh and budget share the entry).
pub(crate) const REDUCE: Stage = Stage { name: "reduce", version: 2 };

/// An impostor level's frames (`impostor::bake_impostor`), rendered on the GPU. 2: each frame
/// shows the mesh's bounds from its direction (`impostor::frame_rects`), not the whole sphere.
/// 4: frames of one grid at whole multiples of each other share one render (the largest,
/// with the smallest one's margins); 3 was never released; 5: frames over 64 texels rendered at
/// fewer samples, near 256 texels a side (`impostor::frame_samples_per_axis`).
pub(crate) const IMPOSTOR: Stage = Stage { name: "impostor", version: 5 };

/// A chain's switch sizes: every level rendered as an engine draws it beside the source, over
/// the 26 views at each screen size of `preview::HOLD_SIZES` (`measure_chain`). 2: a level is
/// measured until it fails at two sizes in a row, not one; 3: 2 × 2 samples a pixel at 128 and
/// 256 px (`preview::hold_samples_per_axis`); 4: a level's candidates cached together, and one
/// outranked by another no longer measured (`preview::holds`); 5: 256 px screened at one sample a
/// pixel first, and figures say their samples; 6: the only candidate left holds at 256 px on its
/// screening when it loses at most `preview::SCREEN_HOLD_LOSS` there.
pub(crate) const SWITCH: Stage = Stage { name: "switch", version: 6 };
/// A reduced level's map surface: its material's source maps packed
/// (`texture::channel_packing`), stored at a level of its mip chain (`reduced::allot_maps`).
pub(crate) const MAPS: Stage = Stage { name: "maps", version: 1 };
/// The cache keys of surfaces stored smaller than they are made (`levels::SurfaceHalvings`).
pub(crate) const SURFACE_HALVINGS: Stage = Stage { name: "surface-halvings", version: 1 };

/// Bounds the kind's memos of images (material textures' mips, renders, atlas coverage and
/// surfaces, impostor frames, reduced meshes; `reduced_queries::keep_memos` their maps) to the
/// `surfaces` used last (see `Kind::keep_memos`): a level makes fewer of each than it has atlas
/// surfaces.
pub(crate) fn keep_memos(db: &mut dyn Db, surfaces: usize) {
    material_texture_mips::set_lru_capacity(db, surfaces);
    plane_images::set_lru_capacity(db, surfaces);
    rendered_batch::set_lru_capacity(db, surfaces);
    atlas_coverage::set_lru_capacity(db, surfaces);
    atlas_texel_sources::set_lru_capacity(db, surfaces);
    atlas_surface::set_lru_capacity(db, surfaces);
    stored_renders::set_lru_capacity(db, surfaces);
    impostor_frames::set_lru_capacity(db, surfaces);
    reduced_level::set_lru_capacity(db, surfaces);
}

/// What a level is asked for (one level without a chain).
#[salsa::tracked(returns(copy))]
pub(crate) fn level_settings(db: &dyn Db, asset: Asset, level: u32) -> super::levels::LevelSettings {
    super::levels::settings_for(asset.settings(db), level)
}

/// A level's stage label: the asset's name, or `asset/lod<N>` in a chain.
#[salsa::tracked(returns(ref))]
pub(crate) fn level_label(db: &dyn Db, asset: Asset, level: u32) -> String {
    super::levels::label(asset.name(db), &super::levels::level_folder(asset.settings(db), level))
}

#[salsa::tracked(returns(copy))]
pub(crate) fn planes_cache_key(db: &dyn Db, asset: Asset, level: u32) -> CacheKey {
    let settings = level_settings(db, asset, level).planes;
    let key = stage_key(PLANES).part(&mesh_cache_key(db, asset, asset.main_file(db).clone()).0);
    match settings.max_quads {
        // ε is searched for: the setting does not enter the key.
        Some(quads) => key.part("budget").part(&quads).part(&settings.max_planes).finish(),
        None => key.part(&settings.epsilon).part(&settings.max_planes).finish(),
    }
}

/// A level's planes (stage `planes`).
#[salsa::tracked(returns(clone))]
pub(crate) fn billboard_planes(
    db: &dyn Db,
    asset: Asset,
    level: u32,
) -> Result<Arc<super::planes::PlaneSet>, Diagnostic> {
    let name = level_label(db, asset, level);
    // Slots asking for the same planes (an `Auto` chain's candidates of one quad count, at
    // every level) share the first one's, even while it is being computed.
    let first = super::levels::first_slot_with_planes(asset.settings(db), level);
    if first != level {
        let planes = billboard_planes(db, asset, first)?;
        record_cache_hit(db, PLANES, name);
        return Ok(planes);
    }
    cached_json(db, PLANES, name, planes_cache_key(db, asset, level), || {
        let loaded = loaded_mesh(db, asset)?;
        let settings = level_settings(db, asset, level).planes;
        let mesh = &loaded.mesh;
        timed(db, PLANES, name, || {
            Ok(match settings.max_quads {
                Some(quads) => super::planes::select_planes_within_budget(
                    &mesh.positions,
                    &mesh.triangles,
                    &mesh.triangle_materials,
                    quads,
                    settings.max_planes,
                    super::planes::SEAM_WEIGHT,
                ),
                None => {
                    super::planes::select_planes(&mesh.positions, &mesh.triangles, &mesh.triangle_materials, settings)
                }
            })
        })
    })
    .map(Arc::new)
}

/// The planes' rectangles and their atlas layout.
#[derive(Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct BillboardLayout {
    pub rectangles: Vec<PlaneRectangle>,
    pub layout: Layout,
    /// The render stages: each plane's rectangles grouped by the materials they show.
    pub render_groups: Vec<RenderGroup>,
}

/// A level's atlas settings, the texel density asked for, and the screen size it is meant for.
#[salsa::tracked(returns(clone))]
pub(crate) fn atlas_layout_settings(
    db: &dyn Db,
    asset: Asset,
    level: u32,
) -> (crate::packing::PageSettings, Option<f32>, Option<u32>) {
    let settings = level_settings(db, asset, level);
    (
        super::levels::level_atlas_settings(&asset.settings(db).own::<Own>().atlas, &settings),
        settings.texel_density,
        settings.screen_size,
    )
}

#[salsa::tracked(returns(copy))]
pub(crate) fn layout_cache_key(db: &dyn Db, asset: Asset, level: u32) -> CacheKey {
    let (atlas, density, screen_size) = atlas_layout_settings(db, asset, level);
    let key = stage_key(LAYOUT).part(&planes_cache_key(db, asset, level).0).part(&atlas).part(&density);
    // Only when given, so that the keys of layouts without it stay as they were.
    match screen_size {
        Some(pixels) => key.part("screen size").part(&pixels).finish(),
        None => key.finish(),
    }
}

/// A level's rectangles, layout and render groups (stage `layout`).
#[salsa::tracked(returns(clone))]
pub(crate) fn billboard_layout(db: &dyn Db, asset: Asset, level: u32) -> Result<Arc<BillboardLayout>, Diagnostic> {
    let label = level_label(db, asset, level);
    cached_json(db, LAYOUT, label, layout_cache_key(db, asset, level), || compute_billboard_layout(db, asset, level))
        .map(Arc::new)
}

fn compute_billboard_layout(db: &dyn Db, asset: Asset, level: u32) -> Result<BillboardLayout, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let planes = billboard_planes(db, asset, level)?;
    let (atlas, density, screen_size) = atlas_layout_settings(db, asset, level);
    // One texel per pixel when the bounding sphere's diameter spans `screen_size` pixels.
    let density = density.or_else(|| {
        let pixels = screen_size? as f32;
        Some(pixels / (2.0 * super::planes::bounding_sphere_radius(&loaded.mesh.positions)))
    });
    timed(db, LAYOUT, level_label(db, asset, level), || {
        let mut rectangles =
            super::rectangles::plane_rectangles(&loaded.mesh.positions, &loaded.mesh.triangles, &planes);
        if let Some(quads) = level_settings(db, asset, level).planes.max_quads {
            rectangles = super::rectangles::merge_rectangles_to_budget(
                &loaded.mesh.positions,
                &loaded.mesh.triangles,
                &planes,
                rectangles,
                quads as usize,
            );
        }
        let solid_materials: Vec<bool> = loaded.mesh.materials.iter().map(|material| !material.cut_out).collect();
        let crack_filling = super::rectangles::CrackFillingInput {
            positions: &loaded.mesh.positions,
            triangles: &loaded.mesh.triangles,
            face_materials: &loaded.mesh.triangle_materials,
            solid_materials: &solid_materials,
        };
        super::rectangles::add_crack_filling_faces(&crack_filling, &planes, &mut rectangles);
        let sizes: Vec<(f32, f32)> =
            rectangles.iter().map(|rectangle| (rectangle.frame.width, rectangle.frame.height)).collect();
        let layout = super::layout::layout_rectangles(&sizes, &atlas, density);
        let render_groups = super::render_groups::render_groups(&loaded.mesh, &rectangles);
        Ok(BillboardLayout { rectangles, layout, render_groups })
    })
}

/// A level's `lod.obj` (stage `lod`): planes and layout only, so texture edits leave it alone.
#[salsa::tracked(returns(clone))]
pub(crate) fn lod_files(db: &dyn Db, asset: Asset, level: u32) -> Result<Arc<String>, Diagnostic> {
    let name = level_label(db, asset, level);
    let key = stage_key(LOD).part(&layout_cache_key(db, asset, level).0).finish();
    cached_json(db, LOD, name, key, || {
        let layout = billboard_layout(db, asset, level)?;
        timed(db, LOD, name, || Ok(super::lod_mesh::lod_mesh(&layout.rectangles, &layout.layout, "billboard_cloud")))
    })
    .map(Arc::new)
}

/// A level's `lod.gltf` and `lod.bin`: planes and layout only (made again after a restart: a
/// few milliseconds, not worth a cache entry).
#[salsa::tracked(returns(clone))]
pub(crate) fn lod_gltf(db: &dyn Db, asset: Asset, level: u32) -> Result<Arc<GltfFiles>, Diagnostic> {
    let layout = billboard_layout(db, asset, level)?;
    let cutoff = billboard_alpha_cutoff(db, asset);
    Ok(Arc::new(super::lod_mesh::lod_gltf(&layout.rectangles, &layout.layout, cutoff)))
}

#[salsa::tracked(returns(copy))]
pub(crate) fn billboard_alpha_cutoff(db: &dyn Db, asset: Asset) -> f32 {
    asset.settings(db).own::<Own>().billboard.alpha_cutoff
}

/// The label of a render group's stage instance: `asset/plane12:bark+leaves`, or
/// `asset/lod1/plane12:bark+leaves` in a chain (`level_label` is the level's).
pub(crate) fn render_label(level_label: &str, mesh: &crate::mesh::Mesh, group: &RenderGroup) -> String {
    format!("{level_label}/{}", super::render_groups::render_group_label(mesh, group))
}

/// A decoded source map of the mesh's material, as a render reads it.
fn material_map(
    db: &dyn Db,
    asset: Asset,
    material: &crate::mesh::MeshMaterial,
    slot: TextureSlot,
) -> Result<Option<Arc<Texture>>, Diagnostic> {
    let mesh_path = asset.main_file(db);
    let Some(path) = material.maps.get(&slot) else { return Ok(None) };
    let Some(file) = asset_file(db, asset, path.clone()) else {
        return Err(Diagnostic::new(mesh_path, format!("texture {} was not read", display_path(path))));
    };
    if let Err(error) = file.contents(db) {
        return Err(Diagnostic::new(
            mesh_path,
            format!("material `{}`: {} texture {}: {error}", material.name, slot.name(), display_path(path)),
        ));
    }
    if slot == TextureSlot::Opacity { opacity_texture(db, file) } else { decoded_texture(db, file) }.map(Some)
}

/// The mip chain the renders sample for a material's texture in `slot` (level 0 is the decoded
/// texture), kept in the persistent cache under the file's content: after a restart, textures
/// that did not change are neither decoded nor filtered again (on the oak, about 50 ms each).
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn material_texture_mips(
    db: &dyn Db,
    asset: Asset,
    material: u32,
    slot: TextureSlot,
) -> Result<Option<Arc<Vec<Texture>>>, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let Some(source) = loaded.mesh.materials.get(material as usize) else { return Ok(None) };
    let Some(path) = source.maps.get(&slot) else { return Ok(None) };
    let contents = asset_file(db, asset, path.clone())
        .and_then(|file| file.contents(db).as_ref().ok().map(|contents| contents.hash));
    let settings = crate::gpu::material_mip_settings(slot, billboard_alpha_cutoff(db, asset));
    let key = contents.map(|hash| {
        stage_key(SOURCE_MIPS)
            .part(&[crate::db::DECODE.version, crate::kinds::tail_queries::MIPS.version])
            .part(&hash)
            .part(slot.name())
            .part(&settings.kind)
            .part(&settings.alpha_cutoff.map_or(u32::MAX, f32::to_bits))
            .finish()
    });
    if let Some(levels) = key.and_then(|key| load_cached(db, SOURCE_MIPS.name, key, mip_levels_from_entry)) {
        return Ok(Some(Arc::new(levels)));
    }
    // A file that could not be read is reported here, with the material that names it.
    let Some(texture) = material_map(db, asset, source, slot)? else { return Ok(None) };
    let levels = Arc::new(crate::texture::mips::mip_chain(&texture, settings));
    if let Some(key) = key {
        let stored = levels.clone();
        store_cached_in_background(db, SOURCE_MIPS.name, key, move || {
            let sizes: Vec<(u32, u32)> = stored.iter().map(|level| (level.width, level.height)).collect();
            CacheEntry::new(&sizes, stored.iter().map(|level| level.pixels.to_vec()).collect(), true)
        });
    }
    Ok(Some(levels))
}

/// The mip chains of source textures in the persistent cache (an entry of the render stage).
const SOURCE_MIPS: Stage = Stage { name: "source-mips", version: 1 };

/// A chain back from its entry; `None` unless every level has its size's bytes and each level
/// halves the one before (a damaged or hand-made entry is a miss).
fn mip_levels_from_entry(entry: CacheEntry) -> Option<Vec<Texture>> {
    let (sizes, blobs) = entry.metadata_and_blobs::<Vec<(u32, u32)>>()?;
    if sizes.is_empty()
        || sizes.len() != blobs.len()
        || sizes.windows(2).any(|pair| pair[1] != ((pair[0].0 / 2).max(1), (pair[0].1 / 2).max(1)))
    {
        return None;
    }
    let fits =
        sizes.iter().zip(&blobs).all(|(&(width, height), pixels)| pixels.len() == width as usize * height as usize * 4);
    fits.then(|| {
        sizes.into_iter().zip(blobs).map(|((width, height), pixels)| Texture::new(width, height, pixels)).collect()
    })
}

/// The images of one render group of a level (four per rectangle, in rectangle order): one
/// plane's rectangles that show the same materials (stage `render`), from the render memo when
/// it holds them, else from its batch's render; reads only the textures of those materials.
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn plane_images(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    group: u32,
) -> Result<Arc<Vec<PlaneImages>>, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let layout = billboard_layout(db, asset, level)?;
    let Some(render_group) = layout.render_groups.get(group as usize) else {
        return Err(Diagnostic::new(asset.main_file(db), format!("render group {group} no longer exists")));
    };
    if let Some(images) = remembered_render(db, asset, level, group) {
        record_cache_hit(db, RENDER, &render_label(level_label(db, asset, level), &loaded.mesh, render_group));
        return Ok(images);
    }
    let batches = level_render_batches(db, asset, level);
    let batch = batches.iter().position(|batch| batch.contains(&group)).expect("every render group is in a batch");
    let rendered = rendered_batch(db, asset, level, batch as u32)?;
    Ok(rendered
        .iter()
        .find(|(rendered, _)| *rendered == group)
        .map(|(_, images)| images.clone())
        .expect("the batch renders its groups"))
}

/// A render group's images from the render memo, when it holds ones that fit the group (a
/// hand-made entry that does not is a miss, never a panic).
fn remembered_render(db: &dyn Db, asset: Asset, level: u32, group: u32) -> Option<Arc<Vec<PlaneImages>>> {
    let layout = billboard_layout(db, asset, level).ok()?;
    let render_group = layout.render_groups.get(group as usize)?;
    let stored = stored_renders(db, asset, level);
    let images = stored.get(&render_group_key(db, asset, level, group))?;
    let fits = images.len() == render_group.rectangles.len()
        && images.iter().zip(&render_group.rectangles).all(|(image, &rectangle)| {
            let placement = &layout.layout.placements[rectangle as usize];
            (image.width, image.height) == (placement.width.max(1), placement.height.max(1))
        });
    fits.then(|| images.clone())
}

/// The level's render groups in the batches that render together (`render_groups::render_batches`).
#[salsa::tracked(returns(clone))]
pub(crate) fn level_render_batches(db: &dyn Db, asset: Asset, level: u32) -> Arc<Vec<Vec<u32>>> {
    let Ok(layout) = billboard_layout(db, asset, level) else { return Arc::default() };
    Arc::new(super::render_groups::render_batches(&layout.render_groups, |group| {
        group
            .rectangles
            .iter()
            .map(|&rectangle| layout.layout.placements[rectangle as usize])
            .map(|p| p.width as u64 * p.height as u64)
            .sum()
    }))
}

/// A render batch's images: each render group's index and its planes' images.
pub(crate) type BatchImages = Vec<(u32, Arc<Vec<PlaneImages>>)>;

/// The images of a batch's render groups that the render memo does not hold, rendered in one
/// go (few GPU submissions for many small groups); each group's run is recorded under its own
/// label with its share of the time, by texels. Every group of a batch shows the same
/// materials, so the batch reads what each of its groups reads.
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn rendered_batch(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    batch: u32,
) -> Result<Arc<BatchImages>, Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let layout = billboard_layout(db, asset, level)?;
    let alpha_cutoff = billboard_alpha_cutoff(db, asset);
    let mesh_path = asset.main_file(db).clone();
    let batches = level_render_batches(db, asset, level);
    let Some(groups) = batches.get(batch as usize) else {
        return Err(Diagnostic::new(&mesh_path, format!("render batch {batch} no longer exists")));
    };
    let groups: Vec<u32> =
        groups.iter().copied().filter(|&group| remembered_render(db, asset, level, group).is_none()).collect();
    let planes = billboard_planes(db, asset, level)?;
    let mut materials = vec![crate::gpu::RenderMaterial::default(); loaded.mesh.materials.len()];
    for &group in &groups {
        for &material_index in &layout.render_groups[group as usize].materials {
            let source = &loaded.mesh.materials[material_index as usize];
            let map = |slot| {
                if loaded.mesh.uvs.is_some() {
                    material_texture_mips(db, asset, material_index, slot)
                } else {
                    Ok(None)
                }
            };
            materials[material_index as usize] = crate::gpu::RenderMaterial {
                albedo: map(TextureSlot::Albedo)?,
                opacity: map(TextureSlot::Opacity)?,
                normal: map(TextureSlot::Normal)?,
                metallic: map(TextureSlot::Metallic)?,
                roughness: map(TextureSlot::Roughness)?,
                ao: map(TextureSlot::Ao)?,
                albedo_factor: [
                    source.albedo_factor[0],
                    source.albedo_factor[1],
                    source.albedo_factor[2],
                    source.opacity,
                ],
                metallic_value: source.metallic,
                roughness_value: source.roughness,
                ao_value: 1.0,
            };
        }
    }
    // The depth range covers every assigned face, also beyond ε when `max_planes` capped them.
    let depth_range = planes.epsilon.max(planes.max_error).max(1e-6);
    let rectangles: Vec<(u32, u32)> = groups
        .iter()
        .flat_map(|&group| {
            layout.render_groups[group as usize].rectangles.iter().map(move |&rectangle| (group, rectangle))
        })
        .collect();
    let texels_of = |rectangle: u32| {
        let placement = &layout.layout.placements[rectangle as usize];
        placement.width.max(1) as f64 * placement.height.max(1) as f64
    };
    let labels: Vec<(String, f64)> = groups
        .iter()
        .map(|&group| {
            let render_group = &layout.render_groups[group as usize];
            let texels = render_group.rectangles.iter().map(|&rectangle| texels_of(rectangle)).sum();
            (render_label(level_label(db, asset, level), &loaded.mesh, render_group), texels)
        })
        .collect();
    let images = timed_together(db, RENDER, &labels, || {
        let gpu = crate::gpu::gpu().map_err(|error| Diagnostic::new(&mesh_path, error.to_string()))?;
        let inputs: Vec<crate::gpu::PlaneRenderInput> = rectangles
            .iter()
            .map(|&(_, rectangle)| {
                let (placement, rectangle) =
                    (&layout.layout.placements[rectangle as usize], &layout.rectangles[rectangle as usize]);
                crate::gpu::PlaneRenderInput {
                    frame: rectangle.frame,
                    epsilon: depth_range,
                    alpha_cutoff,
                    width: placement.width,
                    height: placement.height,
                    supersampling: super::render_groups::plane_supersampling(placement.width, placement.height),
                    batches: crate::gpu::face_batches(
                        &loaded.mesh,
                        &loaded.tangents,
                        rectangle.faces.iter().chain(&rectangle.also_drawn).copied(),
                    ),
                    materials: &materials,
                }
            })
            .collect();
        gpu.render_rectangles(&inputs).map_err(|error| Diagnostic::new(&mesh_path, error.to_string()))
    })?;
    let mut images = images.into_iter();
    let by_group = groups
        .iter()
        .map(|&group| {
            (group, Arc::new(images.by_ref().take(layout.render_groups[group as usize].rectangles.len()).collect()))
        })
        .collect();
    Ok(Arc::new(by_group))
}

/// Every render group's images of a level, in render-group order.
fn render_group_images(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    layout: &BillboardLayout,
) -> Result<Vec<Arc<Vec<PlaneImages>>>, Diagnostic> {
    (0..layout.render_groups.len() as u32).map(|group| plane_images(db, asset, level, group)).collect()
}

/// The images of every rectangle, in layout order: each group's images belong to its
/// rectangles, and every rectangle is in one group.
fn images_by_rectangle<'a>(layout: &BillboardLayout, images: &'a [Arc<Vec<PlaneImages>>]) -> Vec<&'a PlaneImages> {
    let mut by_rectangle: Vec<Option<&PlaneImages>> = vec![None; layout.rectangles.len()];
    for (group, group_images) in layout.render_groups.iter().zip(images) {
        for (&rectangle, image) in group.rectangles.iter().zip(group_images.iter()) {
            by_rectangle[rectangle as usize] = Some(image);
        }
    }
    by_rectangle.into_iter().map(|image| image.expect("every rectangle is in a render group")).collect()
}

/// The atlas texels that faces cover (part of the atlas stage): unchanged by colour-only
/// edits, which therefore skip the fill search below.
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn atlas_coverage(
    db: &dyn Db,
    asset: Asset,
    level: u32,
) -> Result<Arc<super::atlas::AtlasCoverage>, Diagnostic> {
    let layout = billboard_layout(db, asset, level)?;
    let images = render_group_images(db, asset, level, &layout)?;
    store_renders(db, asset, level, &images);
    timed(db, ATLAS, level_label(db, asset, level), || {
        Ok(Arc::new(super::atlas::atlas_coverage(&layout.layout, &images_by_rectangle(&layout, &images))))
    })
}

/// Where each atlas texel takes its values from, uncovered ones by the fill search (part of the
/// atlas stage). Kept in the persistent cache under the coverage's content hash: a colour-only
/// edit in a new process loads it (about 15 ms on the oak) instead of searching (about 90 ms).
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn atlas_texel_sources(
    db: &dyn Db,
    asset: Asset,
    level: u32,
) -> Result<Arc<crate::texture::fill::TexelSources>, Diagnostic> {
    let coverage = atlas_coverage(db, asset, level)?;
    let key = stage_key(ATLAS_FILL).part(&coverage.content_hash()).finish();
    let texels = coverage.width as usize * coverage.height as usize;
    let stored = load_cached(db, ATLAS_FILL.name, key, |entry| {
        let [offsets] = entry.into_blobs::<1>()?;
        crate::texture::fill::TexelSources::from_offsets(&from_pod_blob::<u32>(&offsets)?, texels)
    });
    if let Some(sources) = stored {
        return Ok(Arc::new(sources));
    }
    let sources = timed(db, ATLAS, level_label(db, asset, level), || super::atlas::texel_sources(&coverage));
    if !sources.0.is_empty() {
        let offsets = sources.to_offsets();
        store_cached_in_background(db, ATLAS_FILL.name, key, move || {
            CacheEntry::of_blobs(vec![pod_blob(&offsets)], true)
        });
    }
    Ok(Arc::new(sources))
}

/// The fill search's result in the persistent cache (an entry of the atlas stage).
const ATLAS_FILL: Stage = Stage { name: "atlas-fill", version: 1 };

/// One composited, filled atlas surface of a level (stage `atlas`), shared with the tail, not
/// copied.
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn atlas_surface(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    surface: SurfaceKind,
) -> Result<Arc<Texture>, Diagnostic> {
    let layout = billboard_layout(db, asset, level)?;
    let images = render_group_images(db, asset, level, &layout)?;
    let coverage = atlas_coverage(db, asset, level)?;
    let sources = atlas_texel_sources(db, asset, level)?;
    timed(db, ATLAS, level_label(db, asset, level), || {
        let planes = images_by_rectangle(&layout, &images);
        Ok(Arc::new(super::atlas::composite_atlas_surface(&layout.layout, &planes, &coverage, &sources, surface)))
    })
}

/// What one atlas surface is composited from, once the renders are done: the recipe's layout
/// and cutoff, the coverage, and the bytes of that surface's image of every render group. A
/// texture edit that leaves a surface's renders alone (a colour-only edit leaves the normals)
/// finds it in the cache by this key without compositing it.
#[salsa::tracked(returns(clone))]
pub(crate) fn atlas_surface_parts_key(
    db: &dyn Db,
    asset: Asset,
    level: u32,
    surface: SurfaceKind,
) -> Result<CacheKey, Diagnostic> {
    let layout = billboard_layout(db, asset, level)?;
    let images = render_group_images(db, asset, level, &layout)?;
    let coverage = atlas_coverage(db, asset, level)?;
    let mut hasher = blake3::Hasher::new();
    for group_images in &images {
        for image in group_images.iter() {
            hasher.update(&image.width.to_le_bytes()).update(&image.height.to_le_bytes());
            hasher.update(image.surface(surface));
        }
    }
    let key = stage_key(Stage { name: "atlas-parts", version: 1 })
        .part(&ATLAS.version)
        .part(&layout_cache_key(db, asset, level).0)
        .part(&billboard_alpha_cutoff(db, asset))
        .part(&surface)
        .part(&coverage.content_hash())
        .part(&hasher.finalize());
    Ok(key.finish())
}

/// What the atlas is made of, cheap to compute: the layout's key (mesh, MTL, settings), every
/// texture the materials name, the alpha cutoff, the render and atlas versions.
#[salsa::tracked(returns(copy))]
pub(crate) fn atlas_recipe_key(db: &dyn Db, asset: Asset, level: u32) -> CacheKey {
    let key = stage_key(ATLAS)
        .part(&RENDER.version)
        .part(crate::gpu::adapter_family())
        .part(&layout_cache_key(db, asset, level).0)
        .part(&billboard_alpha_cutoff(db, asset));
    with_mesh_textures(db, asset, key)
}

/// `key` with the contents of every texture the mesh's materials name: what the renders of the
/// atlas and of an impostor's frames sample.
pub(super) fn with_mesh_textures(db: &dyn Db, asset: Asset, key: CacheKeyBuilder) -> CacheKey {
    let textures =
        mesh_textures(db, asset).iter().filter_map(|path| asset_file(db, asset, path.clone())).collect::<Vec<_>>();
    key_with_files(db, key, textures).finish()
}

/// The fraction of atlas texels that faces cover, rounded to 1e-4, for the report: kept in the
/// persistent cache under the atlas's recipe, so that a bake served from the cache needs no atlas.
#[salsa::tracked(returns(clone))]
pub(crate) fn atlas_coverage_fraction(db: &dyn Db, asset: Asset, level: u32) -> Result<f64, Diagnostic> {
    let key =
        stage_key(Stage { name: "atlas-coverage", version: 1 }).part(&atlas_recipe_key(db, asset, level).0).finish();
    cached_json(db, ATLAS, level_label(db, asset, level), key, || {
        let coverage = atlas_coverage(db, asset, level)?;
        let fraction = coverage.drawn.len() as f32 / (coverage.width as usize * coverage.height as usize).max(1) as f32;
        Ok(((fraction * 1e4).round() / 1e4) as f64)
    })
}

/// What one render group's images are made of: the layout (mesh, MTL, planes, settings), the
/// group, the alpha cutoff, and the textures of the group's materials.
#[salsa::tracked(returns(copy))]
pub(crate) fn render_group_key(db: &dyn Db, asset: Asset, level: u32, group: u32) -> CacheKey {
    let key = stage_key(RENDER)
        .part(crate::gpu::adapter_family())
        .part(&layout_cache_key(db, asset, level).0)
        .part(&group)
        .part(&billboard_alpha_cutoff(db, asset));
    let (Ok(loaded), Ok(layout)) = (loaded_mesh(db, asset), billboard_layout(db, asset, level)) else {
        return key.finish();
    };
    let Some(render_group) = layout.render_groups.get(group as usize) else { return key.finish() };
    let mut paths: Vec<&PathBuf> = Vec::new();
    if loaded.mesh.uvs.is_some() {
        for &material in &render_group.materials {
            paths.extend(loaded.mesh.materials[material as usize].maps.values());
        }
    }
    paths.sort();
    paths.dedup();
    let files: Vec<SourceFile> = paths.into_iter().filter_map(|path| asset_file(db, asset, path.clone())).collect();
    key_with_files(db, key, files).finish()
}

/// The render memo on disk, one entry per material set: the images of every render group of
/// the asset's last atlas that shows that set, under the layout's key and the set (overwritten
/// when one of its groups changes), each group's images under its `render_group_key`. Per set,
/// not per group (on the oak, 1,245 entries made a full bake 1.0 s slower) nor one for all: an
/// edit of the bark's texture rewrites the two sets that show bark (9 of the oak's 37 MB).
const RENDER_MEMO: &str = "render-memo";

fn render_memo_key(db: &dyn Db, asset: Asset, level: u32, materials: &[u32]) -> CacheKey {
    stage_key(Stage { name: RENDER_MEMO, version: RENDER.version })
        .part(&layout_cache_key(db, asset, level).0)
        .part(materials)
        .finish()
}

/// The material sets of the layout's render groups, each with its groups' indices.
fn groups_by_material_set(layout: &BillboardLayout) -> BTreeMap<&[u32], Vec<u32>> {
    let mut sets: BTreeMap<&[u32], Vec<u32>> = BTreeMap::new();
    for (index, group) in layout.render_groups.iter().enumerate() {
        sets.entry(group.materials.as_slice()).or_default().push(index as u32);
    }
    sets
}

/// The render groups' images the memo on disk holds, by group key (read once per layout).
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn stored_renders(db: &dyn Db, asset: Asset, level: u32) -> Arc<HashMap<CacheKey, Arc<Vec<PlaneImages>>>> {
    let Ok(layout) = billboard_layout(db, asset, level) else { return Arc::default() };
    let mut renders = HashMap::new();
    for materials in groups_by_material_set(&layout).keys() {
        let key = render_memo_key(db, asset, level, materials);
        renders.extend(load_cached(db, RENDER_MEMO, key, renders_from_entry).unwrap_or_default());
    }
    Arc::new(renders)
}

/// Stores the images of every material set some of whose groups were rendered (not all came
/// from the memo).
fn store_renders(db: &dyn Db, asset: Asset, level: u32, images: &[Arc<Vec<PlaneImages>>]) {
    if db.disk_cache().is_none() {
        return;
    }
    let Ok(layout) = billboard_layout(db, asset, level) else { return };
    let stored = stored_renders(db, asset, level);
    for (materials, groups) in groups_by_material_set(&layout) {
        let keys: Vec<CacheKey> = groups.iter().map(|&group| render_group_key(db, asset, level, group)).collect();
        if keys.iter().all(|key| stored.contains_key(key)) {
            continue;
        }
        // Gathering megabytes of images into one blob happens on the writer's thread.
        let images: Vec<Arc<Vec<PlaneImages>>> = groups.iter().map(|&group| images[group as usize].clone()).collect();
        store_cached_in_background(db, RENDER_MEMO, render_memo_key(db, asset, level, materials), move || {
            let mut groups = Vec::new();
            let mut bytes = Vec::new();
            for (key, group_images) in keys.iter().zip(&images) {
                let sizes: Vec<(u32, u32)> = group_images.iter().map(|image| (image.width, image.height)).collect();
                groups.push((key.0.to_hex().to_string(), sizes));
                for image in group_images.iter() {
                    bytes.extend_from_slice(image.bytes());
                }
            }
            CacheEntry::new(&RenderMemoEntry { groups }, vec![bytes], true)
        });
    }
}

/// What a render memo entry holds beside its images: each group's key (hex) and image sizes.
#[derive(serde::Serialize, serde::Deserialize)]
struct RenderMemoEntry {
    groups: Vec<(String, Vec<(u32, u32)>)>,
}

/// A render memo entry's groups; their images share the entry's blob (nothing is copied).
fn renders_from_entry(entry: CacheEntry) -> Option<HashMap<CacheKey, Arc<Vec<PlaneImages>>>> {
    let (RenderMemoEntry { groups }, [bytes]) = entry.parts::<RenderMemoEntry, 1>()?;
    let buffer = Arc::new(bytes);
    let mut offset = 0;
    let mut renders = HashMap::new();
    for (key, sizes) in groups {
        let key = CacheKey(blake3::Hash::from_hex(key).ok()?);
        let mut images = Vec::new();
        for (width, height) in sizes {
            images.push(PlaneImages::in_buffer(width, height, buffer.clone(), offset)?);
            offset += PlaneImages::byte_len(width, height);
        }
        renders.insert(key, Arc::new(images));
    }
    (offset == buffer.len()).then_some(renders)
}

/// The polygon an asset's impostor levels are drawn as (`impostor::view_hull`): the mesh's
/// outline from every direction, the same for all of them.
#[salsa::tracked(returns(clone))]
pub(crate) fn impostor_hull(db: &dyn Db, asset: Asset) -> Result<[[f32; 2]; 8], Diagnostic> {
    let loaded = loaded_mesh(db, asset)?;
    let (center, radius) = super::planes::bounding_sphere(&loaded.mesh.positions);
    let points: Vec<glam::Vec3> = loaded.mesh.positions.iter().map(|&point| glam::Vec3::from(point)).collect();
    Ok(crate::impostor::view_hull(&points, (center, radius)))
}

/// A reduced level (stage `reduce`): the mesh under the level's triangle budget.
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn reduced_level(
    db: &dyn Db,
    asset: Asset,
    level: u32,
) -> Result<Arc<super::reduced::ReducedLevel>, Diagnostic> {
    let name = level_label(db, asset, level);
    let Some(budget) = level_settings(db, asset, level).reduced else {
        return Err(Diagnostic::new(asset.main_file(db), format!("{name} is not a reduced level")));
    };
    let key = stage_key(REDUCE).part(&mesh_cache_key(db, asset, asset.main_file(db).clone()).0);
    let key = match budget {
        crate::mesh::reduce::TriangleBudget::Triangles(count) => key.part("triangles").part(&count),
        crate::mesh::reduce::TriangleBudget::Ratio(ratio) => key.part("ratio").part(&ratio),
    };
    let key = key.part(&super::reduced::REDUCE_MAX_ERROR).finish();
    let from_entry = |entry: CacheEntry| {
        let (figures, obj, geometry) = crate::kinds::mesh_queries::written_mesh_from_entry(entry)?;
        Some(super::reduced::ReducedLevel { obj, geometry, figures })
    };
    if let Some(reduced) = load_cached(db, REDUCE.name, key, from_entry) {
        record_cache_hit(db, REDUCE, name);
        return Ok(Arc::new(reduced));
    }
    let loaded = loaded_mesh(db, asset)?;
    let reduced = timed(db, REDUCE, name, || Ok(super::reduced::reduce_level(&loaded.mesh, budget)))?;
    crate::db::store_cached(db, REDUCE.name, key, || {
        crate::kinds::mesh_queries::written_mesh_entry(&reduced.figures, &reduced.obj, &reduced.geometry)
    });
    Ok(Arc::new(reduced))
}

/// An impostor level's frames (stage `impostor`): the source with its materials rendered from
/// every direction of the level's grid around the mesh's bounding sphere. Not kept in the
/// persistent cache itself: its surfaces are, under [`impostor_recipe_key`], and a level whose
/// surfaces are all there never asks for it.
#[salsa::tracked(returns(clone), lru = 0)]
pub(crate) fn impostor_frames(
    db: &dyn Db,
    asset: Asset,
    level: u32,
) -> Result<Arc<crate::impostor::ImpostorFrames>, Diagnostic> {
    let name = level_label(db, asset, level);
    let main_file = asset.main_file(db);
    let Some(settings) = level_settings(db, asset, level).impostor else {
        return Err(Diagnostic::new(main_file, format!("{name} is not an impostor level")));
    };
    let render = impostor_render(db, asset, level).expect("an impostor level");
    if render.source != level {
        let source = impostor_frames(db, asset, render.source)?;
        let cutoff = billboard_alpha_cutoff(db, asset);
        return timed(db, IMPOSTOR, name, || {
            Ok(Arc::new(crate::impostor::reduced_frames(&source, render.factor, cutoff)))
        });
    }
    let loaded = loaded_mesh(db, asset)?;
    let view = source_view_mesh(db, asset, &loaded)?;
    let sphere = super::planes::bounding_sphere(&loaded.mesh.positions);
    timed(db, IMPOSTOR, name, || {
        let gpu = crate::gpu::gpu().map_err(|error| Diagnostic::new(main_file, error.to_string()))?;
        // Cancellable between batches of frames: a 32 × 32 grid of 256² frames takes minutes on a
        // software adapter, and an edit back to a cheaper level must not wait for it.
        let frames = crate::db::stoppable(db, |should_stop| {
            match crate::impostor::bake_impostor_with_margin(
                gpu,
                &view,
                sphere,
                (settings, render.margin_frame),
                should_stop,
            ) {
                Err(crate::gpu::GpuError::Stopped) => Err(crate::stop::Stopped),
                frames => Ok(frames),
            }
        })
        .map_err(|error| Diagnostic::new(main_file, format!("{name}: {error}")))?;
        Ok(Arc::new(frames))
    })
}

/// How an impostor level's frames are made (`levels::impostor_render`; none: not an impostor).
#[salsa::tracked(returns(copy))]
pub(crate) fn impostor_render(db: &dyn Db, asset: Asset, level: u32) -> Option<super::levels::ImpostorRender> {
    super::levels::impostor_render(asset.settings(db), level)
}

/// What an impostor level's surfaces are made of: the mesh (with its MTL), the frames, the
/// alpha cutoff, every texture the materials name, the GPU family that renders them.
#[salsa::tracked(returns(copy))]
pub(crate) fn impostor_recipe_key(db: &dyn Db, asset: Asset, level: u32) -> CacheKey {
    let settings = level_settings(db, asset, level).impostor;
    let (frames, hemi, frame_size) =
        settings.map_or((0, false, 0), |settings| (settings.grid.frames, settings.grid.is_hemi(), settings.frame_size));
    // The frames it is reduced from (their size) and the margins they share.
    let render = impostor_render(db, asset, level);
    let rendered_size = render.map_or(0, |render| frame_size * render.factor);
    let key = stage_key(IMPOSTOR)
        .part(crate::gpu::adapter_family())
        .part(&mesh_cache_key(db, asset, asset.main_file(db).clone()).0)
        .part(&frames)
        .part(&hemi)
        .part(&frame_size)
        .part(&rendered_size)
        .part(&render.map_or(0, |render| render.margin_frame))
        .part(&billboard_alpha_cutoff(db, asset));
    with_mesh_textures(db, asset, key)
}

/// The source mesh with its decoded maps (mipmapped as for rendering).
pub(super) fn source_view_mesh(
    db: &dyn Db,
    input: Asset,
    loaded: &LoadedMesh,
) -> Result<crate::gpu::ViewMesh, Diagnostic> {
    let cutoff = input.settings(db).own::<Own>().billboard.alpha_cutoff;
    crate::preview::mesh_view(&loaded.mesh, &loaded.tangents, cutoff, |material, slot| {
        let Some(path) = material.maps.get(&slot).filter(|_| loaded.mesh.uvs.is_some()) else { return Ok(None) };
        let Some(file) = crate::db::asset_file(db, input, path.clone()) else { return Ok(None) };
        match slot {
            TextureSlot::Opacity => crate::db::opacity_texture(db, file).map(Some),
            _ => crate::db::decoded_texture(db, file).map(Some),
        }
    })
}
