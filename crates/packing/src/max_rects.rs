//! MaxRects (Jylänki 2010, "A thousand ways to pack the bin") onto one or more pages: every
//! placement rule and input order tried, the smallest page kept. Rectangles are cells of whole
//! 4×4 blocks (content plus `padding` texels each side, rounded up), so that no BC block ever
//! holds texels of two entries. Deterministic: integer scores, ties broken by input index and
//! variant order, whatever thread ran which variant.

use std::sync::atomic::{AtomicU64, Ordering};

use rayon::prelude::*;

use super::Placement;

/// How rectangles go onto pages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageSettings {
    /// Largest page side in texels (a multiple of 4).
    pub max_size: u32,
    /// Texels kept around every rectangle's content.
    pub padding: u32,
    /// Whether a rectangle may be turned 90°.
    pub rotate: bool,
    /// Page sides are powers of two.
    pub power_of_two: bool,
    /// Most pages the rectangles may take.
    pub pages: u32,
}

/// Where MaxRects puts the next rectangle among the free ones.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub(crate) enum PlacementRule {
    /// The free rectangle whose shorter leftover side is smallest.
    BestShortSideFit,
    /// The free rectangle whose longer leftover side is smallest.
    BestLongSideFit,
    /// The smallest free rectangle that fits.
    BestAreaFit,
    /// The lowest top edge, then the leftmost.
    BottomLeft,
    /// The most edge length touching the page's border or placed rectangles.
    ContactPoint,
}

/// In which order the rectangles are placed (largest first by each measure).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub(crate) enum SortOrder {
    Area,
    MaxSide,
    MinSide,
    Perimeter,
}

const RULES: [PlacementRule; 5] = [
    PlacementRule::BestShortSideFit,
    PlacementRule::BestLongSideFit,
    PlacementRule::BestAreaFit,
    PlacementRule::BottomLeft,
    PlacementRule::ContactPoint,
];
const ORDERS: [SortOrder; 4] = [SortOrder::Area, SortOrder::MaxSide, SortOrder::MinSide, SortOrder::Perimeter];

/// One way of packing: a rule and an order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub(crate) struct PackVariant {
    pub rule: PlacementRule,
    pub order: SortOrder,
}

/// Every variant, in the order that breaks ties.
pub(crate) fn pack_variants() -> Vec<PackVariant> {
    ORDERS.iter().flat_map(|&order| RULES.iter().map(move |&rule| PackVariant { rule, order })).collect()
}

/// A rectangle's place: its page and its placement there (content, in texels).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PagePlacement {
    pub page: u32,
    pub placement: Placement,
}

/// The pages (width, height in texels) and where each input rectangle went, in input order.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PagePacking {
    pub pages: Vec<(u32, u32)>,
    pub placements: Vec<PagePlacement>,
}

impl PagePacking {
    /// Content texels over page texels.
    pub fn occupancy(&self) -> f64 {
        let content: u64 =
            self.placements.iter().map(|place| place.placement.width as u64 * place.placement.height as u64).sum();
        let pages: u64 = self.pages.iter().map(|&(width, height)| width as u64 * height as u64).sum();
        content as f64 / pages.max(1) as f64
    }
}

/// Why rectangles could not be packed.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PackError {
    #[error(
        "rectangle {index} is {width}×{height} texels with its padding, larger than a page of at most \
        {max_size}×{max_size}"
    )]
    TooLarge { index: usize, width: u32, height: u32, max_size: u32 },
    #[error(
        "{left} of {count} rectangles ({left_texels} texels with padding) do not fit on {pages} page(s) of at most \
            {max_size}×{max_size}"
    )]
    DoesNotFit { count: usize, left: usize, left_texels: u64, pages: u32, max_size: u32 },
}

/// Packs `sizes` (content width and height in texels) onto as few and as small pages as
/// `settings` allow: one page when they fit on one (the smallest, squarest found), else full
/// pages of `max_size` and a last page as small as its rectangles allow.
pub fn pack_pages(sizes: &[(u32, u32)], settings: &PageSettings) -> Result<PagePacking, PackError> {
    let max_blocks = settings.max_size / 4;
    let cells: Vec<Cell> = sizes
        .iter()
        .map(|&(width, height)| Cell {
            width: (width + 2 * settings.padding).div_ceil(4).max(1),
            height: (height + 2 * settings.padding).div_ceil(4).max(1),
        })
        .collect();
    for (index, cell) in cells.iter().enumerate() {
        // Pages are square at their largest: turning a cell does not make it fit.
        if cell.width > max_blocks || cell.height > max_blocks {
            return Err(PackError::TooLarge {
                index,
                width: cell.width * 4,
                height: cell.height * 4,
                max_size: settings.max_size,
            });
        }
    }
    let mut left: Vec<usize> = (0..cells.len()).collect();
    let mut pages = Vec::new();
    let mut placements =
        vec![
            PagePlacement { page: 0, placement: Placement { x: 0, y: 0, width: 0, height: 0, rotated: false } };
            sizes.len()
        ];
    loop {
        let page = pages.len() as u32;
        let subset: Vec<Cell> = left.iter().map(|&index| cells[index]).collect();
        // The rest fits on one page: the smallest one.
        if let Some(found) = smallest_page(&subset, settings) {
            for (&index, cell_place) in left.iter().zip(&found.places) {
                placements[index] = page_placement(
                    page,
                    cell_place.expect("a page search places everything"),
                    sizes[index],
                    settings.padding,
                );
            }
            pages.push((found.width * 4, found.height * 4));
            return Ok(PagePacking { pages, placements });
        }
        // A full page: the variant that places the most area on it.
        let full = full_page(&subset, max_blocks, settings.rotate);
        let mut still_left = Vec::new();
        for (&index, cell_place) in left.iter().zip(&full.places) {
            match cell_place {
                Some(place) => placements[index] = page_placement(page, *place, sizes[index], settings.padding),
                None => still_left.push(index),
            }
        }
        if page + 1 >= settings.pages {
            let left_texels =
                still_left.iter().map(|&index| cells[index].width as u64 * cells[index].height as u64 * 16).sum();
            return Err(PackError::DoesNotFit {
                count: sizes.len(),
                left: still_left.len(),
                left_texels,
                pages: settings.pages,
                max_size: settings.max_size,
            });
        }
        assert!(still_left.len() < left.len(), "every rectangle fits an empty page (checked above)");
        pages.push((max_blocks * 4, max_blocks * 4));
        left = still_left;
    }
}

/// How [`pack_pages_keeping`] went.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Repack {
    /// The previous layout was kept: only these rectangles (input indices) were placed anew (new
    /// ones, and ones whose size changed), in free space.
    Kept { placed: Vec<usize> },
    /// Everything was packed afresh: the kept layout would have been too wasteful (below 90 % of
    /// a fresh pack's occupancy) or could not take the new rectangles.
    Repacked,
}

/// Like [`pack_pages`], keeping the `previous` layout (the last packing of the same settings:
/// its pages, and each rectangle's place if it had one) as a hint: rectangles of unchanged size
/// stay where they were, the others go into free space on the same pages. A fresh pack replaces
/// it only when the kept layout cannot take them or its occupancy falls below 90 % of the fresh
/// one's; a previous layout that does not fit the settings (other padding, larger than
/// `max_size`, overlapping) is not kept.
pub fn pack_pages_keeping(
    sizes: &[(u32, u32)],
    settings: &PageSettings,
    previous_pages: &[(u32, u32)],
    previous: &[Option<PagePlacement>],
) -> Result<(PagePacking, Repack), PackError> {
    let fresh = pack_pages(sizes, settings)?;
    let kept = keep_layout(sizes, settings, previous_pages, previous);
    Ok(match kept {
        Some((packing, placed)) if packing.occupancy() >= 0.9 * fresh.occupancy() => (packing, Repack::Kept { placed }),
        _ => (fresh, Repack::Repacked),
    })
}

/// The previous layout with the rectangles it lacks added in free space; `None` when it does
/// not fit the settings or cannot take them.
fn keep_layout(
    sizes: &[(u32, u32)],
    settings: &PageSettings,
    previous_pages: &[(u32, u32)],
    previous: &[Option<PagePlacement>],
) -> Option<(PagePacking, Vec<usize>)> {
    let page_fits = |&(width, height): &(u32, u32)| {
        width % 4 == 0
            && height % 4 == 0
            && width <= settings.max_size
            && height <= settings.max_size
            && (!settings.power_of_two || (width.is_power_of_two() && height.is_power_of_two()))
    };
    if previous_pages.is_empty()
        || previous_pages.len() as u32 > settings.pages
        || !previous_pages.iter().all(page_fits)
    {
        return None;
    }
    let mut bins: Vec<Bin> =
        previous_pages.iter().map(|&(width, height)| Bin::new(width / 4, height / 4, false)).collect();
    let cell_of = |(width, height): (u32, u32), rotated: bool| {
        let (span_x, span_y) = if rotated { (height, width) } else { (width, height) };
        ((span_x + 2 * settings.padding).div_ceil(4), (span_y + 2 * settings.padding).div_ceil(4))
    };
    let mut placements: Vec<Option<PagePlacement>> = vec![None; sizes.len()];
    let mut taken: Vec<Vec<Rect>> = vec![Vec::new(); bins.len()];
    for (index, &size) in sizes.iter().enumerate() {
        let Some(old) = previous.get(index).copied().flatten() else { continue };
        let placement = old.placement;
        if (placement.width, placement.height) != size || (placement.rotated && !settings.rotate) {
            continue;
        }
        let (Some(x), Some(y)) = (placement.x.checked_sub(settings.padding), placement.y.checked_sub(settings.padding))
        else {
            return None;
        };
        let (width, height) = cell_of(size, placement.rotated);
        let cell = Rect { x: x / 4, y: y / 4, width, height };
        let page = old.page as usize;
        let inside = page < bins.len() && cell.right() <= bins[page].width && cell.bottom() <= bins[page].height;
        if x % 4 != 0 || y % 4 != 0 || !inside || taken[page].iter().any(|other| other.intersects(&cell)) {
            return None;
        }
        taken[page].push(cell);
        bins[page].place(cell);
        placements[index] = Some(old);
    }
    // The rest, largest first, into the first page with room (best short side fit there).
    let mut placed: Vec<usize> = (0..sizes.len()).filter(|&index| placements[index].is_none()).collect();
    placed.sort_by_key(|&index| (std::cmp::Reverse(sizes[index].0 as u64 * sizes[index].1 as u64), index));
    for &index in &placed {
        let (width, height) = cell_of(sizes[index], false);
        let (page, place) = bins.iter().enumerate().find_map(|(page, bin)| {
            Some((page, bin.find(width, height, settings.rotate, PlacementRule::BestShortSideFit)?))
        })?;
        let (w, h) = if place.rotated { (height, width) } else { (width, height) };
        bins[page].place(Rect { x: place.x, y: place.y, width: w, height: h });
        placements[index] = Some(page_placement(page as u32, place, sizes[index], settings.padding));
    }
    placed.sort_unstable();
    let placements = placements.into_iter().map(|place| place.expect("every rectangle placed")).collect();
    Some((PagePacking { pages: previous_pages.to_vec(), placements }, placed))
}

fn page_placement(page: u32, place: CellPlace, (width, height): (u32, u32), padding: u32) -> PagePlacement {
    PagePlacement {
        page,
        placement: Placement {
            x: place.x * 4 + padding,
            y: place.y * 4 + padding,
            width,
            height,
            rotated: place.rotated,
        },
    }
}

/// A rectangle in blocks, padding included.
#[derive(Clone, Copy, Debug)]
struct Cell {
    width: u32,
    height: u32,
}

/// Where a cell went, in blocks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct CellPlace {
    x: u32,
    y: u32,
    rotated: bool,
}

/// One packing of cells into a `width` × `height` block page.
struct Packed {
    width: u32,
    height: u32,
    places: Vec<Option<CellPlace>>,
}

/// The smallest page (by area, then squarest, then variant order) on which one variant places
/// every cell, within `max_size`; `None` when no variant places them all on the largest page.
fn smallest_page(cells: &[Cell], settings: &PageSettings) -> Option<Packed> {
    let max_blocks = settings.max_size / 4;
    let area: u64 = cells.iter().map(|cell| cell.width as u64 * cell.height as u64).sum();
    // No page is narrower than the widest cell can be made.
    let narrowest = cells
        .iter()
        .map(|cell| if settings.rotate { cell.width.min(cell.height) } else { cell.width })
        .max()
        .unwrap_or(1);
    let round = |side: u32| if settings.power_of_two { side.next_power_of_two() } else { side };
    let first_width = round(narrowest.max((area as f64).sqrt().ceil() as u32).max(1));
    if first_width > max_blocks {
        return None;
    }
    let variants = pack_variants();
    // The smallest page area found so far: a strip whose cells already need more is given up
    // (a page of equal area finishes, so ties are broken the same whichever thread was first).
    let smallest_area = AtomicU64::new(u64::MAX);
    let strip = |variant: PackVariant, width: u32| -> Option<Packed> {
        let places = max_rects(cells, width, max_blocks, variant, Some(&smallest_area), settings.rotate)?;
        let height = places.iter().zip(cells).map(|(place, cell)| {
            let place = place.expect("all placed");
            place.y + if place.rotated { cell.width } else { cell.height }
        });
        let height = round(height.max().unwrap_or(1).max(1));
        if height > max_blocks {
            // Rounded up past the largest page: not a page, so not a bound on the others.
            return None;
        }
        smallest_area.fetch_min(width as u64 * height as u64, Ordering::Relaxed);
        Some(Packed { width, height, places })
    };
    let better = |a: &Packed, b: &Packed| {
        let key = |packed: &Packed| (packed.width as u64 * packed.height as u64, packed.width.abs_diff(packed.height));
        key(a) < key(b)
    };
    let wider = if settings.power_of_two {
        std::iter::successors(Some(first_width * 2), |width| Some(width * 2))
            .take_while(|&width| width <= max_blocks)
            .take(2)
            .collect()
    } else {
        (1..=6u32)
            .map(|step| first_width + (first_width * step).div_ceil(16))
            .filter(|&width| width <= max_blocks)
            .collect::<Vec<_>>()
    };
    // Every variant on strips of every width, at once: the bound gives up on the losers early.
    // Pages of the smallest area always finish, so the one kept (by area, squareness, then the
    // order of the trials) does not depend on which thread finished first.
    let smallest = |widths: &[u32]| -> Option<Packed> {
        let trials: Vec<(PackVariant, u32)> =
            widths.iter().flat_map(|&width| variants.iter().map(move |&variant| (variant, width))).collect();
        let packed: Vec<Option<Packed>> = trials.par_iter().map(|&(variant, width)| strip(variant, width)).collect();
        let mut best: Option<Packed> = None;
        for packed in packed.into_iter().flatten() {
            if best.as_ref().is_none_or(|best| better(&packed, best)) {
                best = Some(packed);
            }
        }
        best
    };
    let widths: Vec<u32> = std::iter::once(first_width).chain(wider).collect();
    // When strips narrower than the page all fail, the whole largest page.
    smallest(&widths).or_else(|| smallest(&[max_blocks]))
}

/// The variant that places the most cell area on a full `side` × `side` page.
fn full_page(cells: &[Cell], side: u32, rotate: bool) -> Packed {
    let variants = pack_variants();
    let tries: Vec<Packed> = variants
        .par_iter()
        .map(|&variant| {
            let places = max_rects(cells, side, side, variant, None, rotate).expect("partial packing always succeeds");
            Packed { width: side, height: side, places }
        })
        .collect();
    let placed_area = |packed: &Packed| -> u64 {
        packed
            .places
            .iter()
            .zip(cells)
            .filter(|(place, _)| place.is_some())
            .map(|(_, cell)| cell.width as u64 * cell.height as u64)
            .sum()
    };
    let mut best: Option<Packed> = None;
    for packed in tries {
        if best.as_ref().is_none_or(|best| placed_area(&packed) > placed_area(best)) {
            best = Some(packed);
        }
    }
    best.expect("at least one variant")
}

/// Places `cells` in `variant`'s order on a `width` × `height` block page. With an area bound
/// (packing a strip), `None` as soon as one does not fit or the cells placed reach below
/// `bound / width`; without, the ones that do not fit are `None` in the result.
fn max_rects(
    cells: &[Cell],
    width: u32,
    height: u32,
    variant: PackVariant,
    area_bound: Option<&AtomicU64>,
    rotate: bool,
) -> Option<Vec<Option<CellPlace>>> {
    let mut order: Vec<usize> = (0..cells.len()).collect();
    let key = |cell: &Cell| -> (u64, u64) {
        let (long, short) = (cell.width.max(cell.height) as u64, cell.width.min(cell.height) as u64);
        match variant.order {
            SortOrder::Area => (long * short, long),
            SortOrder::MaxSide => (long, short),
            SortOrder::MinSide => (short, long),
            SortOrder::Perimeter => (long + short, long),
        }
    };
    order.sort_by_key(|&index| (std::cmp::Reverse(key(&cells[index])), index));
    let mut bin = Bin::new(width, height, variant.rule == PlacementRule::ContactPoint);
    let mut places = vec![None; cells.len()];
    let mut used_height = 0;
    for index in order {
        let cell = cells[index];
        match bin.find(cell.width, cell.height, rotate, variant.rule) {
            Some(place) => {
                let (w, h) = if place.rotated { (cell.height, cell.width) } else { (cell.width, cell.height) };
                bin.place(Rect { x: place.x, y: place.y, width: w, height: h });
                places[index] = Some(place);
                used_height = used_height.max(place.y + h);
                if area_bound.is_some_and(|bound| width as u64 * used_height as u64 > bound.load(Ordering::Relaxed)) {
                    return None;
                }
            }
            None if area_bound.is_some() => return None,
            None => {}
        }
    }
    Some(places)
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Rect {
    x: u32,
    y: u32,
    width: u32,
    height: u32,
}

impl Rect {
    fn right(&self) -> u32 {
        self.x + self.width
    }
    fn bottom(&self) -> u32 {
        self.y + self.height
    }
    fn intersects(&self, other: &Rect) -> bool {
        self.x < other.right() && other.x < self.right() && self.y < other.bottom() && other.y < self.bottom()
    }
    fn contains(&self, other: &Rect) -> bool {
        self.x <= other.x && self.y <= other.y && other.right() <= self.right() && other.bottom() <= self.bottom()
    }
}

/// A page being packed: its maximal free rectangles, and for the contact-point rule a map of
/// the blocks taken.
struct Bin {
    width: u32,
    height: u32,
    free: Vec<Rect>,
    taken: Option<Vec<bool>>,
}

impl Bin {
    fn new(width: u32, height: u32, track_taken: bool) -> Bin {
        Bin {
            width,
            height,
            free: vec![Rect { x: 0, y: 0, width, height }],
            taken: track_taken.then(|| vec![false; width as usize * height as usize]),
        }
    }

    /// The best place for a `width` × `height` cell by `rule` (smallest score; ties: the free
    /// rectangle listed first, unrotated first).
    fn find(&self, width: u32, height: u32, rotate: bool, rule: PlacementRule) -> Option<CellPlace> {
        let mut best: Option<((i64, i64), CellPlace)> = None;
        for free in &self.free {
            for rotated in [false, true] {
                if rotated && (!rotate || width == height) {
                    continue;
                }
                let (w, h) = if rotated { (height, width) } else { (width, height) };
                if w > free.width || h > free.height {
                    continue;
                }
                let (leftover_x, leftover_y) = ((free.width - w) as i64, (free.height - h) as i64);
                let score = match rule {
                    PlacementRule::BestShortSideFit => (leftover_x.min(leftover_y), leftover_x.max(leftover_y)),
                    PlacementRule::BestLongSideFit => (leftover_x.max(leftover_y), leftover_x.min(leftover_y)),
                    PlacementRule::BestAreaFit => {
                        (free.width as i64 * free.height as i64 - w as i64 * h as i64, leftover_x.min(leftover_y))
                    }
                    PlacementRule::BottomLeft => ((free.y + h) as i64, free.x as i64),
                    PlacementRule::ContactPoint => (-(self.contact(free.x, free.y, w, h) as i64), (free.y + h) as i64),
                };
                if best.is_none_or(|(best_score, _)| score < best_score) {
                    best = Some((score, CellPlace { x: free.x, y: free.y, rotated }));
                }
            }
        }
        best.map(|(_, place)| place)
    }

    /// Edge length (in blocks) of a rectangle at (x, y) touching the page's border or taken
    /// blocks.
    fn contact(&self, x: u32, y: u32, width: u32, height: u32) -> u32 {
        let taken = self.taken.as_ref().expect("contact point tracks taken blocks");
        let stride = self.width as usize;
        let is_taken = |column: u32, row: u32| taken[row as usize * stride + column as usize];
        let mut contact = 0;
        if y == 0 {
            contact += width;
        } else {
            contact += (x..x + width).filter(|&column| is_taken(column, y - 1)).count() as u32;
        }
        if y + height == self.height {
            contact += width;
        } else {
            contact += (x..x + width).filter(|&column| is_taken(column, y + height)).count() as u32;
        }
        if x == 0 {
            contact += height;
        } else {
            contact += (y..y + height).filter(|&row| is_taken(x - 1, row)).count() as u32;
        }
        if x + width == self.width {
            contact += height;
        } else {
            contact += (y..y + height).filter(|&row| is_taken(x + width, row)).count() as u32;
        }
        contact
    }

    /// Takes `used`: every free rectangle it overlaps is split into the (up to four) maximal
    /// free rectangles around it, and free rectangles inside others are dropped.
    fn place(&mut self, used: Rect) {
        if let Some(taken) = self.taken.as_mut() {
            for row in used.y..used.bottom() {
                let start = row as usize * self.width as usize;
                taken[start + used.x as usize..start + used.right() as usize].fill(true);
            }
        }
        let mut split = Vec::new();
        let mut index = 0;
        while index < self.free.len() {
            let free = self.free[index];
            if !free.intersects(&used) {
                index += 1;
                continue;
            }
            if used.y > free.y {
                split.push(Rect { height: used.y - free.y, ..free });
            }
            if used.bottom() < free.bottom() {
                split.push(Rect { y: used.bottom(), height: free.bottom() - used.bottom(), ..free });
            }
            if used.x > free.x {
                split.push(Rect { width: used.x - free.x, ..free });
            }
            if used.right() < free.right() {
                split.push(Rect { x: used.right(), width: free.right() - used.right(), ..free });
            }
            self.free.swap_remove(index);
        }
        // Only new rectangles can be inside others or hold others: first among themselves, then
        // against the old ones in one pass (an old one inside a new one goes; a new one inside
        // an old one, or equal to it, is not added).
        let mut new: Vec<Rect> = Vec::with_capacity(split.len());
        for (index, rect) in split.iter().enumerate() {
            let inside_new = split
                .iter()
                .enumerate()
                .any(|(other, bigger)| other != index && bigger.contains(rect) && (bigger != rect || other < index));
            if !inside_new {
                new.push(*rect);
            }
        }
        let mut added = vec![true; new.len()];
        self.free.retain(|free| {
            let mut keep = true;
            for (rect, added) in new.iter().zip(added.iter_mut()) {
                if free.contains(rect) {
                    *added = false;
                } else if rect.contains(free) {
                    keep = false;
                }
            }
            keep
        });
        self.free.extend(new.iter().zip(&added).filter(|(_, &added)| added).map(|(rect, _)| *rect));
    }
}
