//! The dependency graph of a project as plain data (source files, stage instances, artifacts and
//! the reads between them), and its DOT, JSON and Mermaid renderings for `cirrus graph`.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write;

use serde::Serialize;

#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum NodeKind {
    File,
    Stage,
    Artifact,
}

/// One node: `id` is unique; stage ids read `stage(instance)` as in the event log.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Node {
    pub id: String,
    pub kind: NodeKind,
    pub label: String,
    /// The asset the node belongs to; `None` for files shared by several assets.
    pub asset: Option<String>,
    /// The revision of the node's last run (stages), content change (files) or write (artifacts).
    pub revision: Option<u64>,
    /// Duration of the stage's last run in milliseconds.
    pub ms: Option<f64>,
    /// Stages: `ran`, `cached`, `failed` or `pending` (not built yet); files: `present` or
    /// `missing`; artifacts: `written` or `pending`.
    pub state: String,
}

#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
pub struct Edge {
    pub from: String,
    pub to: String,
}

/// The graph: nodes in id order, edges `from` → `to` meaning "`to` read `from`".
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Graph {
    pub nodes: Vec<Node>,
    pub edges: Vec<Edge>,
}

/// Collects nodes and edges without duplicates.
#[derive(Default)]
pub(crate) struct GraphBuilder {
    nodes: BTreeMap<String, Node>,
    edges: BTreeSet<Edge>,
}

impl GraphBuilder {
    /// Adds `node` unless a node with its id exists (the first description wins).
    pub fn node(&mut self, node: Node) {
        self.nodes.entry(node.id.clone()).or_insert(node);
    }

    pub fn edge(&mut self, from: &str, to: &str) {
        self.edges.insert(Edge { from: from.to_string(), to: to.to_string() });
    }

    pub fn finish(self) -> Graph {
        Graph { nodes: self.nodes.into_values().collect(), edges: self.edges.into_iter().collect() }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GraphFormat {
    Dot,
    Json,
    Mermaid,
}

impl GraphFormat {
    pub const ALL: [GraphFormat; 3] = [GraphFormat::Dot, GraphFormat::Json, GraphFormat::Mermaid];

    /// The name on the command line and in the protocol.
    pub fn name(self) -> &'static str {
        match self {
            GraphFormat::Dot => "dot",
            GraphFormat::Json => "json",
            GraphFormat::Mermaid => "mermaid",
        }
    }
}

impl Graph {
    /// The ids of every node reachable from `id` along the edges (not `id` itself).
    pub fn downstream(&self, id: &str) -> BTreeSet<String> {
        let mut next: BTreeMap<&str, Vec<&str>> = BTreeMap::new();
        for edge in &self.edges {
            next.entry(edge.from.as_str()).or_default().push(edge.to.as_str());
        }
        let mut seen = BTreeSet::new();
        let mut stack = vec![id];
        while let Some(current) = stack.pop() {
            for &to in next.get(current).map(Vec::as_slice).unwrap_or_default() {
                if seen.insert(to.to_string()) {
                    stack.push(to);
                }
            }
        }
        seen
    }

    /// Whether any node belongs to `asset`.
    pub fn has_asset(&self, asset: &str) -> bool {
        self.nodes.iter().any(|node| node.asset.as_deref() == Some(asset))
    }

    /// The part of the graph that belongs to `asset` or feeds it, however far upstream (a
    /// shared decode and the texture file it reads).
    pub(crate) fn for_asset(&self, asset: &str) -> Graph {
        let mut keep: BTreeSet<&str> = self
            .nodes
            .iter()
            .filter(|node| node.asset.as_deref() == Some(asset))
            .map(|node| node.id.as_str())
            .collect();
        let mut pending: Vec<&str> = keep.iter().copied().collect();
        while let Some(id) = pending.pop() {
            for edge in self.edges.iter().filter(|edge| edge.to == id) {
                if keep.insert(edge.from.as_str()) {
                    pending.push(edge.from.as_str());
                }
            }
        }
        Graph {
            nodes: self.nodes.iter().filter(|node| keep.contains(node.id.as_str())).cloned().collect(),
            edges: self
                .edges
                .iter()
                .filter(|edge| keep.contains(edge.from.as_str()) && keep.contains(edge.to.as_str()))
                .cloned()
                .collect(),
        }
    }

    pub fn render(&self, format: GraphFormat) -> String {
        match format {
            GraphFormat::Json => serde_json::to_string_pretty(self).expect("graphs serialise") + "\n",
            GraphFormat::Dot => self.to_dot(),
            GraphFormat::Mermaid => self.to_mermaid(),
        }
    }

    fn node_caption(node: &Node) -> String {
        let mut caption = node.label.clone();
        match (node.revision, node.ms) {
            (Some(revision), Some(ms)) => caption += &format!("\nr{revision} · {ms:.1} ms · {}", node.state),
            (Some(revision), None) => caption += &format!("\nr{revision} · {}", node.state),
            _ => caption += &format!("\n{}", node.state),
        }
        caption
    }

    fn to_dot(&self) -> String {
        let quote =
            |text: &str| format!("\"{}\"", text.replace('\\', "\\\\").replace('"', "\\\"").replace('\n', "\\n"));
        let mut text = String::from("digraph cirrus {\n  rankdir=LR;\n  node [fontname=\"Helvetica\", fontsize=10];\n");
        for node in &self.nodes {
            let (shape, colour) = match (node.kind, node.state.as_str()) {
                (NodeKind::File, "missing") => ("note", "#f4b6b6"),
                (NodeKind::File, _) => ("note", "#e8eef7"),
                (NodeKind::Stage, "ran") => ("box", "#ffe9a8"),
                (NodeKind::Stage, "failed") => ("box", "#f4b6b6"),
                (NodeKind::Stage, _) => ("box", "#ffffff"),
                (NodeKind::Artifact, _) => ("folder", "#d9f2d9"),
            };
            let _ = writeln!(
                text,
                "  {} [label={}, shape={shape}, style=filled, fillcolor=\"{colour}\"];",
                quote(&node.id),
                quote(&Self::node_caption(node))
            );
        }
        for edge in &self.edges {
            let _ = writeln!(text, "  {} -> {};", quote(&edge.from), quote(&edge.to));
        }
        text.push_str("}\n");
        text
    }

    fn to_mermaid(&self) -> String {
        // Mermaid ids must be plain words: number the nodes.
        let index: BTreeMap<&str, usize> =
            self.nodes.iter().enumerate().map(|(i, node)| (node.id.as_str(), i)).collect();
        let mut text = String::from("flowchart LR\n");
        for (i, node) in self.nodes.iter().enumerate() {
            let caption = Self::node_caption(node).replace('"', "#quot;").replace('\n', "<br/>");
            let (open, close) = match node.kind {
                NodeKind::File => ("[/", "/]"),
                NodeKind::Stage => ("[", "]"),
                NodeKind::Artifact => ("[(", ")]"),
            };
            let _ = writeln!(text, "  n{i}{open}\"{caption}\"{close}");
        }
        for edge in &self.edges {
            if let (Some(from), Some(to)) = (index.get(edge.from.as_str()), index.get(edge.to.as_str())) {
                let _ = writeln!(text, "  n{from} --> n{to}");
            }
        }
        for (i, node) in self.nodes.iter().enumerate() {
            if node.kind == NodeKind::Stage && node.state == "ran" {
                let _ = writeln!(text, "  style n{i} fill:#ffe9a8");
            } else if node.state == "failed" || node.state == "missing" {
                let _ = writeln!(text, "  style n{i} fill:#f4b6b6");
            }
        }
        text
    }
}
