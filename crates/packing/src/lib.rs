//! Rectangle packing, shared by every kind that lays texels out on a page. `pack_smallest`:
//! cells (whole BC blocks) packed bottom-left along a skyline, 90° rotation allowed, `padding`
//! texels around each, in the smallest (power-of-two when asked) page within `max_size` (the
//! billboard atlas). `max_rects`: MaxRects over several rules and orders onto one or more pages
//! (the texture atlas).

pub mod max_rects;

/// The page a billboard atlas is packed onto: its largest side, the padding around each
/// rectangle, and whether its sides are powers of two.
#[derive(Clone, Debug, PartialEq, Eq, Hash, serde::Serialize)]
pub struct PageSettings {
    pub max_size: u32,
    pub padding: u32,
    pub power_of_two: bool,
}

/// Where one rectangle landed, in texels (the content, without its padding).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Placement {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
    /// The rectangle's X axis runs along the atlas's Y axis.
    pub rotated: bool,
}

/// The smallest atlas (by area, then squarest) that holds `cells`, if any within `max_size`.
pub fn pack_smallest(cells: &[(u32, u32)], settings: &PageSettings) -> Option<(u32, u32, Vec<Placement>)> {
    let padding = settings.padding;
    let padded_area: u64 = cells.iter().map(|&(w, h)| (w + 2 * padding) as u64 * (h + 2 * padding) as u64).sum();
    let largest = cells.iter().map(|&(w, h)| w.min(h) + 2 * padding).max().unwrap_or(4);
    let round = |side: u32| {
        if settings.power_of_two {
            side.next_power_of_two()
        } else {
            side.div_ceil(4) * 4
        }
    };
    let mut widths: Vec<u32> = Vec::new();
    let mut width = round(largest.max((padded_area as f64).sqrt() as u32 / 2).max(4));
    while width <= settings.max_size {
        widths.push(width);
        width = if settings.power_of_two { width * 2 } else { round(width + (width / 8).max(4)) };
    }
    let mut best: Option<(u32, u32, Vec<Placement>)> = None;
    for width in widths {
        let Some((height, placements)) = pack_skyline(cells, width, padding) else {
            continue;
        };
        let height = round(height.max(4));
        if height > settings.max_size {
            continue;
        }
        let better = best.as_ref().is_none_or(|(w, h, _)| {
            let (area, best_area) = (width as u64 * height as u64, *w as u64 * *h as u64);
            area < best_area || (area == best_area && width.abs_diff(height) < w.abs_diff(*h))
        });
        if better {
            best = Some((width, height, placements));
        }
    }
    best
}

/// Bottom-left skyline packing into `width` columns, tallest cells first, each placed in the
/// orientation that keeps the skyline lowest. Returns the used height.
fn pack_skyline(cells: &[(u32, u32)], width: u32, padding: u32) -> Option<(u32, Vec<Placement>)> {
    let mut order: Vec<usize> = (0..cells.len()).collect();
    order.sort_by_key(|&index| {
        (
            std::cmp::Reverse(cells[index].0.max(cells[index].1)),
            std::cmp::Reverse(cells[index].0.min(cells[index].1)),
            index,
        )
    });
    // Skyline segments: (x, y, width).
    let mut skyline: Vec<(u32, u32, u32)> = vec![(0, 0, width)];
    let mut placements = vec![Placement { x: 0, y: 0, width: 0, height: 0, rotated: false }; cells.len()];
    let mut used_height = 0;
    for index in order {
        let (w, h) = cells[index];
        let mut best: Option<(u32, u32, usize, bool)> = None; // (top, x, segment, rotated)
        for rotated in [false, true] {
            let (cell_w, cell_h) =
                if rotated { (h + 2 * padding, w + 2 * padding) } else { (w + 2 * padding, h + 2 * padding) };
            if cell_w > width {
                continue;
            }
            for segment in 0..skyline.len() {
                let x = skyline[segment].0;
                if x + cell_w > width {
                    break;
                }
                // The cell rests on the highest segment under its span.
                let mut y = 0;
                let mut covered = 0;
                let mut next = segment;
                while covered < cell_w {
                    y = y.max(skyline[next].1);
                    covered += skyline[next].2;
                    next += 1;
                    if next >= skyline.len() && covered < cell_w {
                        break;
                    }
                }
                let top = y + cell_h;
                if best.is_none_or(|(best_top, best_x, _, _)| (top, x) < (best_top, best_x)) {
                    best = Some((top, x, segment, rotated));
                }
            }
        }
        let (top, x, _, rotated) = best?;
        let (cell_w, cell_h) =
            if rotated { (h + 2 * padding, w + 2 * padding) } else { (w + 2 * padding, h + 2 * padding) };
        let y = top - cell_h;
        placements[index] = Placement { x: x + padding, y: y + padding, width: w, height: h, rotated };
        used_height = used_height.max(top);
        // Raise the skyline over [x, x + cell_w) to `top`.
        let mut updated: Vec<(u32, u32, u32)> = Vec::with_capacity(skyline.len() + 2);
        for &(sx, sy, sw) in &skyline {
            let end = sx + sw;
            if end <= x || sx >= x + cell_w {
                updated.push((sx, sy, sw));
                continue;
            }
            if sx < x {
                updated.push((sx, sy, x - sx));
            }
            if end > x + cell_w {
                updated.push((x + cell_w, sy, end - (x + cell_w)));
            }
        }
        updated.push((x, top, cell_w));
        updated.sort_by_key(|segment| segment.0);
        // Merge neighbours of equal height.
        skyline.clear();
        for segment in updated {
            match skyline.last_mut() {
                Some(last) if last.1 == segment.1 && last.0 + last.2 == segment.0 => last.2 += segment.2,
                _ => skyline.push(segment),
            }
        }
    }
    Some((used_height, placements))
}

impl Placement {
    /// The atlas texel position (continuous, origin top-left, rows down) of the point at
    /// `(s, t)` ∈ [0, 1]² of the rectangle (s along its X axis, t along its Y axis, Y up).
    pub fn atlas_position(&self, s: f32, t: f32) -> (f32, f32) {
        if self.rotated {
            (self.x as f32 + t * self.height as f32, self.y as f32 + s * self.width as f32)
        } else {
            (self.x as f32 + s * self.width as f32, self.y as f32 + (1.0 - t) * self.height as f32)
        }
    }

    /// The OBJ texture coordinate (v up, origin bottom-left) of `(s, t)` in an atlas of
    /// `width` × `height` texels.
    pub fn uv(&self, s: f32, t: f32, width: u32, height: u32) -> [f32; 2] {
        let (x, y) = self.atlas_position(s, t);
        [x / width as f32, 1.0 - y / height as f32]
    }
}
