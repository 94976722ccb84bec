//! The one list of asset kinds: each kind's name (in `pipeline.ron`, summaries and reports) and
//! its folder under `kinds/` (a crate, re-exported as `kinds::<folder>`). `kinds/entries` makes of it
//! the enum of `pipeline.ron` entries, the names a rule's `kind:` takes and every kind's `KIND`;
//! the driver asks a kind through its `AssetKind` and names none. Adding a kind adds one line here.

/// Calls `$callback! { Name => folder, … }` with every kind, in the order summaries list them.
macro_rules! with_kinds {
    ($callback:ident) => {
        $callback! {
            Material => material,
            BillboardCloud => billboard_cloud,
            Atlas => atlas,
            AmbientOcclusion => ambient_occlusion,
            Height => height,
        }
    };
}
