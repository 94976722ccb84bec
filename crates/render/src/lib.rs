//! What cirrus draws through the GPU for people and engines: previews of baked assets (contact
//! sheets, a view of a LOD chain) and octahedral impostor atlases with their reference renders.

pub mod impostor;
pub mod preview;
