//! The tests of the packing library, one binary (as the application's `tests/it`).

mod max_rects;
