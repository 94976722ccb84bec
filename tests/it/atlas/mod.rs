//! The `Atlas` kind (being built): its page composite and trim, over the shared packer.

mod bake;
mod page;
