//! The tests of the texture library, one binary (as the application's `tests/it`): a module per
//! library module under test.

mod distance_alpha;
