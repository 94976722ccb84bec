//! The page packer (`packing::max_rects`): every rectangle inside its page, none overlapping with
//! its padding, cells on whole blocks, several pages when one is not enough, and clear errors.

use packing::max_rects::{pack_pages, PackError, PageSettings};

/// `count` sizes from 1 to `largest` texels a side, from a fixed seed (sprites and props:
/// mostly small, some large, any aspect).
fn mixed_sizes(count: usize, largest: u32, seed: u64) -> Vec<(u32, u32)> {
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 33) as u32
    };
    (0..count)
        .map(|_| {
            let scale = 1 << (next() % largest.ilog2());
            (1 + next() % (2 * scale).min(largest), 1 + next() % (2 * scale).min(largest))
        })
        .collect()
}

/// Asserts what every packing must be: each content rectangle of the right size, inside its page
/// with its padding, its cell (content and padding, rounded up to blocks) starting on a block,
/// no two cells overlapping, rotation only where allowed.
fn assert_valid(sizes: &[(u32, u32)], settings: &PageSettings, packing: &packing::max_rects::PagePacking) {
    assert_eq!(packing.placements.len(), sizes.len());
    assert!(packing.pages.len() as u32 <= settings.pages);
    for &(width, height) in &packing.pages {
        assert!(
            width <= settings.max_size && height <= settings.max_size && width % 4 == 0 && height % 4 == 0,
            "{width}×{height}"
        );
        if settings.power_of_two {
            assert!(width.is_power_of_two() && height.is_power_of_two(), "{width}×{height}");
        }
    }
    let padding = settings.padding;
    let cells: Vec<(u32, [u32; 4])> = packing
        .placements
        .iter()
        .zip(sizes)
        .map(|(place, &(width, height))| {
            let p = place.placement;
            assert_eq!((p.width, p.height), (width, height));
            assert!(settings.rotate || !p.rotated);
            let (span_x, span_y) = if p.rotated { (height, width) } else { (width, height) };
            let (x0, y0) = (p.x - padding, p.y - padding);
            assert_eq!((x0 % 4, y0 % 4), (0, 0), "cells start on a block: {p:?}");
            let (x1, y1) = (x0 + (span_x + 2 * padding).div_ceil(4) * 4, y0 + (span_y + 2 * padding).div_ceil(4) * 4);
            let (page_width, page_height) = packing.pages[place.page as usize];
            assert!(x1 <= page_width && y1 <= page_height, "{p:?} outside its {page_width}×{page_height} page");
            (place.page, [x0, y0, x1, y1])
        })
        .collect();
    for (index, (page, a)) in cells.iter().enumerate() {
        for (page_b, b) in &cells[index + 1..] {
            let overlap = page == page_b && a[0] < b[2] && b[0] < a[2] && a[1] < b[3] && b[1] < a[3];
            assert!(!overlap, "cells {a:?} and {b:?} overlap on page {page}");
        }
    }
}

#[test]
fn packed_rectangles_lie_inside_their_page_on_whole_blocks_and_never_overlap() {
    let sizes = mixed_sizes(300, 256, 7);
    for (padding, rotate, power_of_two) in [(0, true, false), (2, true, true), (4, false, false), (3, false, true)] {
        let settings = PageSettings { max_size: 4096, padding, rotate, power_of_two, pages: 1 };
        let packing = pack_pages(&sizes, &settings).unwrap();
        assert_valid(&sizes, &settings, &packing);
        assert_eq!(packing.pages.len(), 1);
        assert!(packing.placements.iter().any(|place| place.placement.rotated) == rotate, "rotation used when allowed");
        // Cells (content with padding, on whole blocks) cover nearly all of a free-sized page;
        // a power-of-two page is the smallest one that holds them, so more than half is used.
        let cells: u64 = packing
            .placements
            .iter()
            .map(|place| {
                let p = place.placement;
                ((p.width + 2 * padding).div_ceil(4) * 4) as u64 * ((p.height + 2 * padding).div_ceil(4) * 4) as u64
            })
            .sum();
        let page = packing.pages[0].0 as u64 * packing.pages[0].1 as u64;
        let least = if power_of_two { 0.5 } else { 0.95 };
        assert!(
            cells as f64 / page as f64 > least,
            "padding {padding}, rotate {rotate}: {cells} cell texels on {:?}",
            packing.pages
        );
    }
}

#[test]
fn packing_is_the_same_every_time_whichever_thread_finishes_first() {
    // Variants run in parallel and give up once a smaller page is known: the page kept must not
    // depend on their timing.
    let sizes = mixed_sizes(500, 256, 3);
    let settings = PageSettings { max_size: 4096, padding: 2, rotate: true, power_of_two: false, pages: 2 };
    let first = pack_pages(&sizes, &settings).unwrap();
    for _ in 0..10 {
        assert_eq!(pack_pages(&sizes, &settings).unwrap(), first);
    }
}

#[test]
fn equal_squares_that_tile_a_page_exactly_fill_it() {
    let sizes = vec![(32, 32); 64];
    let settings = PageSettings { max_size: 1024, padding: 0, rotate: true, power_of_two: true, pages: 1 };
    let packing = pack_pages(&sizes, &settings).unwrap();
    assert_valid(&sizes, &settings, &packing);
    assert_eq!(packing.pages, [(256, 256)]);
    assert_eq!(packing.occupancy(), 1.0);
}

#[test]
fn rectangles_that_do_not_fit_one_page_fill_several_and_the_last_is_as_small_as_it_can_be() {
    let sizes = mixed_sizes(400, 128, 11);
    let settings = PageSettings { max_size: 512, padding: 2, rotate: true, power_of_two: false, pages: 8 };
    let packing = pack_pages(&sizes, &settings).unwrap();
    assert_valid(&sizes, &settings, &packing);
    assert!(packing.pages.len() >= 2, "{:?}", packing.pages);
    let (full, last) = packing.pages.split_at(packing.pages.len() - 1);
    assert!(full.iter().all(|&page| page == (512, 512)), "{:?}", packing.pages);
    assert!(last[0].0 * last[0].1 < 512 * 512, "{:?}", packing.pages);
    // The same rectangles on too few pages: how much did not fit.
    let error = pack_pages(&sizes, &PageSettings { pages: 1, ..settings }).unwrap_err();
    let PackError::DoesNotFit { count, left, pages, .. } = error else { panic!("{error}") };
    assert_eq!((count, pages), (400, 1));
    assert!(left > 0 && left < 400, "{left}");
    assert!(error.to_string().contains("do not fit on 1 page(s) of at most 512×512"), "{error}");
}

#[test]
fn a_rectangle_larger_than_a_page_is_named() {
    let settings = PageSettings { max_size: 256, padding: 4, rotate: true, power_of_two: false, pages: 4 };
    let error = pack_pages(&[(16, 16), (252, 10)], &settings).unwrap_err();
    assert_eq!(error, PackError::TooLarge { index: 1, width: 260, height: 20, max_size: 256 });
    assert_eq!(
        error.to_string(),
        "rectangle 1 is 260×20 texels with its padding, larger than a page of at most 256×256"
    );
}

#[test]
fn a_kept_layout_moves_nothing_and_new_rectangles_go_into_free_space() {
    use packing::max_rects::{pack_pages_keeping, Repack};
    let settings = PageSettings { max_size: 2048, padding: 2, rotate: true, power_of_two: true, pages: 2 };
    let sizes = mixed_sizes(120, 128, 5);
    let first = pack_pages(&sizes, &settings).unwrap();
    let previous: Vec<_> = first.placements.iter().copied().map(Some).collect();
    // The same sizes (a pixel edit): nothing moves.
    let (same, how) = pack_pages_keeping(&sizes, &settings, &first.pages, &previous).unwrap();
    assert_eq!((same.clone(), how), (first.clone(), Repack::Kept { placed: vec![] }));
    // One more rectangle, and one resized: the others stay, those two go into free space.
    let mut grown = sizes.clone();
    grown[7] = (grown[7].0 + 9, grown[7].1);
    grown.push((20, 36));
    let mut hint = previous.clone();
    hint.push(None);
    let (kept, how) = pack_pages_keeping(&grown, &settings, &first.pages, &hint).unwrap();
    assert_eq!(how, Repack::Kept { placed: vec![7, 120] });
    assert_valid(&grown, &settings, &kept);
    for index in (0..120).filter(|&index| index != 7) {
        assert_eq!(kept.placements[index], first.placements[index], "rectangle {index} stays");
    }
    // Most rectangles gone: the kept page would be mostly empty, so everything is packed anew.
    let few = &sizes[..10];
    let (repacked, how) = pack_pages_keeping(few, &settings, &first.pages, &previous[..10]).unwrap();
    assert_eq!(how, Repack::Repacked);
    assert_eq!(repacked, pack_pages(few, &settings).unwrap());
    // A hint that does not fit the settings (other padding: cells off the block grid, or
    // overlapping) is not kept.
    let (_, how) =
        pack_pages_keeping(&sizes, &PageSettings { padding: 3, ..settings }, &first.pages, &previous).unwrap();
    assert_eq!(how, Repack::Repacked);
    let mut overlapping = previous.clone();
    overlapping[1] = overlapping[0].map(|mut place| {
        place.placement.width = sizes[1].0;
        place.placement.height = sizes[1].1;
        place
    });
    let (_, how) = pack_pages_keeping(&sizes, &settings, &first.pages, &overlapping).unwrap();
    assert_eq!(how, Repack::Repacked);
}

#[test]
fn new_rectangles_that_the_kept_pages_cannot_take_make_a_fresh_pack() {
    use packing::max_rects::{pack_pages_keeping, Repack};
    let settings = PageSettings { max_size: 1024, padding: 0, rotate: false, power_of_two: true, pages: 4 };
    let sizes = vec![(64, 64); 16];
    let first = pack_pages(&sizes, &settings).unwrap();
    assert_eq!(first.pages, [(256, 256)]);
    let previous: Vec<_> = first.placements.iter().copied().map(Some).collect();
    let mut more = sizes.clone();
    more.extend([(128, 128); 4]);
    let mut hint = previous;
    hint.extend([None; 4]);
    let (packing, how) = pack_pages_keeping(&more, &settings, &first.pages, &hint).unwrap();
    assert_eq!(how, Repack::Repacked);
    assert_valid(&more, &settings, &packing);
}
