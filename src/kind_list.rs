//! The one list of asset kinds: each kind's name (in `pipeline.ron`, summaries and reports) and
//! its folder under `kinds/`. `config` makes the `AssetKind` enum of it, `kinds/entries` the enum of
//! `pipeline.ron` entries, and `kinds` the dispatch of every question the driver asks
//! (`kinds::Kind`); adding a kind adds one line here.

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
