//! The `Atlas` kind (DESIGN §3.5), being built: so far its pure steps (`page`: trim, page
//! composite; `table`: `atlas.json` and the UV transform) over the shared packer
//! (`packing::max_rects`) and fill (`texture::fill`). The `Kind` answers, inputs by glob and the
//! mesh remap come next (issue 14).

pub mod page;
pub mod table;
