//! The `Atlas` kind (DESIGN §3.5), being built: so far its pure steps (`page`: trim, page
//! composite) over the shared packer (`packing::max_rects`) and fill (`texture::fill`); the
//! `Kind` answers, inputs by glob, the table and the mesh remap come next (issue 14).

pub mod page;
