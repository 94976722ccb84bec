//! The `Atlas` kind (DESIGN §3.5): textures named by globs, trimmed, equal ones merged, packed
//! onto pages (`packing::max_rects`), each page composited (`page`) and sent through the shared
//! tail as `atlas.ktx2` / `atlas_N.ktx2`, with the table `atlas.json` (`table`). The last layout
//! is the packer's hint (`pack_pages_keeping`), so an edit moves nothing; the last page is the
//! composite's start, so an edit re-composites its own rectangle.

pub mod page;
pub mod queries;
pub mod table;

use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::cache::CacheKey;
use crate::config::{AssetConfig, AssetSource, PipelineConfig};
use crate::db::{Asset, Db, StageRun, DECODE};
use crate::diagnostic::{display_path, Diagnostic};
use crate::kinds::{check_texture_file, tail_instances, AssetOutputs, Job, Kind, Read, StageInstance, SurfaceId, Task};
use crate::texture::tail::TailSettings;
use crate::texture::{SurfaceKind, Texture};

use queries::{
    atlas_layout, atlas_layout_and_change, atlas_page, atlas_texture_files, page_group, page_label, page_recipe_key, page_stem, COMPOSITE,
    LAYOUT, TRIM,
};
use table::{uv_transform, AtlasEntry, AtlasPage, AtlasTable};

pub struct Atlas;

/// The tail surface of page `page`.
fn page_surface(page: u32) -> SurfaceId {
    SurfaceId { group: page_group(page), surface: SurfaceKind::Albedo }
}

/// The page a surface of this kind is.
fn surface_page(surface: &SurfaceId) -> Option<u32> {
    surface.group.strip_prefix("page")?.parse().ok()
}

/// A page's texture and preview files.
fn page_files(output_folder: &Path, page: u32, container: crate::config::Container) -> [PathBuf; 2] {
    let stem = page_stem(page);
    [output_folder.join(format!("{stem}.{}", container.extension())), output_folder.join(format!("{stem}.png"))]
}

impl Kind for Atlas {
    const NAME: &'static str = "Atlas";

    fn files_to_read(db: &dyn Db, asset: Asset) -> Vec<PathBuf> {
        asset.listed(db).iter().flatten().cloned().collect()
    }

    fn first_jobs(db: &dyn Db, asset: Asset) -> Vec<Job> {
        vec![Job { asset, task: Task::Step("layout", 0), after: 0, label: asset.name(db).clone() }]
    }

    fn run_step(db: &dyn Db, asset: Asset, step: &'static str, _index: u32) -> Result<Vec<Job>, Diagnostic> {
        match step {
            "layout" => {
                let layout = atlas_layout(db, asset)?;
                let name = asset.name(db);
                Ok((0..layout.packing.pages.len() as u32)
                    .map(|page| Job { asset, task: Task::Surface(page_surface(page)), after: 1, label: page_surface(page).label(name) })
                    .collect())
            }
            other => unreachable!("the atlas kind schedules no step `{other}`"),
        }
    }

    fn stage_instances(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &[Diagnostic]) -> Vec<StageInstance> {
        let name = asset.name(db);
        let report = output_folder.join("report.json");
        let mut pack = StageInstance::new(LAYOUT, name, name);
        let mut instances = Vec::new();
        for path in atlas_texture_files(db, asset) {
            let label = display_path(path);
            let mut decode = StageInstance::new(DECODE, &label, &label);
            decode.reads.push(Read::File(path.clone()));
            decode.shared = true;
            let mut trim = StageInstance::new(TRIM, &label, &label).reads_stage(&decode);
            trim.shared = true;
            pack = pack.reads_stage(&trim);
            instances.extend([decode, trim]);
        }
        pack.writes = vec![output_folder.join("atlas.json"), report.clone()];
        let container = asset.settings(db).encode.container;
        let layout = atlas_layout(db, asset).ok();
        let pages = layout.as_ref().map_or(0, |layout| layout.packing.pages.len() as u32);
        let mut tails = Vec::new();
        for page in 0..pages {
            // A page reads the layout, and the texels of its own entries only.
            let mut composite = StageInstance::new(COMPOSITE, page_label(name, page), page_group(page)).reads_stage(&pack);
            let layout = layout.as_ref().expect("pages come from the layout");
            for (entry, _) in layout.entries.iter().zip(&layout.packing.placements).filter(|(_, place)| place.page == page) {
                composite.reads.push(Read::Stage(DECODE, display_path(&entry.file)));
            }
            let [mips, encode, mut write] =
                tail_instances(name, &page_surface(page), &composite, page_files(output_folder, page, container));
            write.writes.push(report.clone());
            tails.extend([composite, mips, encode, write]);
        }
        instances.insert(0, pack);
        instances.extend(tails);
        for instance in &mut instances {
            instance.failed = !errors.is_empty();
        }
        instances
    }

    fn outputs(db: &dyn Db, asset: Asset, output_folder: &Path, errors: &mut Vec<Diagnostic>, runs: &[StageRun]) -> AssetOutputs {
        if !errors.is_empty() {
            return AssetOutputs::default();
        }
        match atlas_outputs(db, asset, output_folder, runs) {
            Ok(outputs) => outputs,
            Err(diagnostic) => {
                errors.push(diagnostic);
                AssetOutputs::default()
            }
        }
    }

    /// Every texture the globs match is readable and within the limits; globs that match
    /// nothing are an error.
    fn check(config: &PipelineConfig, asset: &AssetConfig) -> Vec<Diagnostic> {
        let AssetSource::Atlas { textures, .. } = &asset.source else { return Vec::new() };
        let files = crate::sources::glob_matches(config, textures);
        if files.is_empty() {
            return vec![Diagnostic::new(&config.source, format!("atlas `{}`: no texture matches {textures:?}", asset.name))];
        }
        files.iter().filter_map(|path| check_texture_file(config, path).err().map(|message| Diagnostic::new(path, message))).collect()
    }

    fn surface_image(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Arc<Texture>, Diagnostic> {
        let page =
            surface_page(surface).ok_or_else(|| Diagnostic::new(asset.source_root(db), format!("no atlas page {}", surface.group)))?;
        atlas_page(db, asset, page)
    }

    fn tail_settings(db: &dyn Db, asset: Asset, _surface: &SurfaceId) -> Result<TailSettings, Diagnostic> {
        let encode = &asset.settings(db).encode;
        Ok(TailSettings {
            surface: SurfaceKind::Albedo,
            format: encode.albedo,
            quality: encode.quality,
            mips: encode.mips,
            alpha_cutoff: None,
            container: encode.container,
            zstd: encode.zstd,
        })
    }

    fn surface_recipe_key(db: &dyn Db, asset: Asset, surface: &SurfaceId) -> Result<Option<CacheKey>, Diagnostic> {
        surface_page(surface).map(|page| page_recipe_key(db, asset, page)).transpose()
    }
}

/// The pages, their previews, `atlas.json` and the report.
fn atlas_outputs(db: &dyn Db, asset: Asset, output_folder: &Path, runs: &[StageRun]) -> Result<AssetOutputs, Diagnostic> {
    let laid_out = atlas_layout_and_change(db, asset)?;
    let (layout, change) = (&laid_out.0, &laid_out.1);
    let container = asset.settings(db).encode.container;
    let mut outputs = AssetOutputs::default();
    let mut pages = Vec::new();
    let mut surfaces = Vec::new();
    for (page, &(width, height)) in layout.packing.pages.iter().enumerate() {
        let page = page as u32;
        let artifacts = crate::kinds::tail_queries::surface_artifacts(db, asset, page_surface(page))?;
        let [texture_path, preview_path] = page_files(output_folder, page, container);
        pages.push(AtlasPage { file: display_path(texture_path.strip_prefix(output_folder).unwrap_or(&texture_path)), width, height });
        outputs.files.push((texture_path, artifacts.texture_file.clone()));
        outputs.files.push((preview_path, artifacts.preview_png.clone()));
        surfaces.push(artifacts.info.clone());
    }
    let mut entries: Vec<AtlasEntry> = layout
        .entries
        .iter()
        .zip(&layout.packing.placements)
        .map(|(entry, place)| {
            let placement = place.placement;
            let page_size = layout.packing.pages[place.page as usize];
            let (uv_offset, uv_scale) = uv_transform(&placement, entry.trim, entry.source_size, page_size);
            AtlasEntry {
                name: entry.name.clone(),
                page: place.page,
                x: placement.x,
                y: placement.y,
                width: placement.width,
                height: placement.height,
                rotated: placement.rotated,
                source_size: entry.source_size,
                trim_offset: [entry.trim.x, entry.trim.y],
                uv_offset,
                uv_scale,
                aliases: entry.aliases.clone(),
            }
        })
        .collect();
    entries.sort_by(|a, b| a.name.cmp(&b.name));
    let table = AtlasTable { pages, entries };
    outputs.files.push((output_folder.join("atlas.json"), table.to_json().into_bytes().into()));
    let report = serde_json::json!({
        "asset": asset.name(db),
        "kind": Atlas::NAME,
        "entries": layout.entries.len(),
        "textures": atlas_texture_files(db, asset).len(),
        "pages": layout.packing.pages,
        "occupancy": (layout.packing.occupancy() * 1e4).round() / 1e4,
        "layout": change,
        "surfaces": surfaces,
        "stage_ms": crate::kinds::asset_stage_ms(asset.name(db), runs),
    });
    outputs.report = Some(serde_json::to_vec_pretty(&report).expect("reports serialise"));
    Ok(outputs)
}
