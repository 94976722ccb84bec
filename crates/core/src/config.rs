//! `pipeline.ron`: parsed in two levels, a serde mirror of the file (`raw`) and then validated,
//! resolved per-asset settings (`PipelineConfig`). The shared parts are here (folders, rules,
//! limits, cache, `encode`); each kind's entry and sections are its own (`KindEntry`), given as
//! the list of kinds (`EntryKinds`). Every error names the file, line and column.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use crate::diagnostic::{Diagnostic, TextPosition};
use base::paths::normalize_relative_path;

pub mod sections;
mod encode;
pub use encode::*;
mod settings;
pub use settings::Settings;
mod entry;
pub use entry::{AssetReference, EntryCheck, EntryKinds, KindEntry, KindFields, KindSettings};

/// A kind of asset: its name (in `pipeline.ron`'s `kind:`, summaries and reports) and the
/// questions the driver asks it, held here without their type (`kinds::KindQuestions`: they read
/// the database, which stands above `config`). Each kind's folder makes its own (`KIND`); two are
/// the same kind when their names are.
#[derive(Clone, Copy)]
pub struct AssetKind {
    name: &'static str,
    questions: &'static (dyn std::any::Any + Send + Sync),
}

impl AssetKind {
    pub const fn new(name: &'static str, questions: &'static (dyn std::any::Any + Send + Sync)) -> AssetKind {
        AssetKind { name, questions }
    }

    /// The kind's name in `pipeline.ron`, summaries and reports.
    pub fn name(self) -> &'static str {
        self.name
    }

    /// The questions the driver asks the kind, as its folder made them.
    pub fn questions(self) -> &'static (dyn std::any::Any + Send + Sync) {
        self.questions
    }
}

impl PartialEq for AssetKind {
    fn eq(&self, other: &AssetKind) -> bool {
        self.name == other.name
    }
}

impl Eq for AssetKind {}

impl std::hash::Hash for AssetKind {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.name.hash(state);
    }
}

impl std::fmt::Debug for AssetKind {
    /// As the enum it stands for printed (`Material`): the record's configuration hash is made of
    /// this text.
    fn fmt(&self, formatter: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        formatter.write_str(self.name)
    }
}

/// What an asset is made from: its kind, the file it is named after, and the globs whose
/// matches it reads, whatever its kind (a kind's other files are its settings').
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct AssetSource {
    pub kind: AssetKind,
    /// Relative to the source folder: a `.mymaterial`, a billboard's or AO's OBJ, a Height's low
    /// mesh; empty for an asset named by globs alone (what concerns the whole asset is then
    /// said of the source folder).
    pub main_file: PathBuf,
    /// The lists of globs (over the source folder) whose matches the asset reads, in the order
    /// its kind takes them (an atlas: textures, then meshes); none for kinds that name files.
    pub glob_lists: Vec<Vec<String>>,
}

impl AssetSource {
    /// An asset named after one file.
    pub fn of_file(kind: AssetKind, main_file: impl Into<PathBuf>) -> AssetSource {
        AssetSource { kind, main_file: main_file.into(), glob_lists: Vec::new() }
    }

    pub fn kind(&self) -> AssetKind {
        self.kind
    }

    pub fn main_file(&self) -> &Path {
        &self.main_file
    }

    pub fn glob_lists(&self) -> Vec<&[String]> {
        self.glob_lists.iter().map(Vec::as_slice).collect()
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct AssetConfig {
    pub name: String,
    pub source: AssetSource,
    pub settings: Settings,
}

/// A glob over the source folder whose matches become assets.
#[derive(Clone, Debug)]
pub struct Rule {
    pub glob: String,
    pub matcher: globset::GlobMatcher,
    pub kind: AssetKind,
    /// The settings of the assets it makes: its kind's, from `defaults:`.
    pub settings: Settings,
}

/// The validated pipeline.
#[derive(Clone, Debug)]
pub struct PipelineConfig {
    /// The `pipeline.ron` file itself.
    pub file: PathBuf,
    /// The folder holding `pipeline.ron`; every other path is inside it.
    pub root: PathBuf,
    /// The watched source folder, relative to `root`.
    pub source: PathBuf,
    /// The artifact folder, relative to `root`.
    pub output: PathBuf,
    pub server: Option<SocketAddr>,
    pub assets: Vec<AssetConfig>,
    pub rules: Vec<Rule>,
    pub limits: Limits,
    /// The shared cache behind the local one (`cache: (remote: …, mode: …)`), before the
    /// command line's or the environment's override.
    pub remote_cache: Option<crate::cache::remote::RemoteCacheSettings>,
}

/// The memory budgets `limits: (memory_mib: …)` and `--memory-mib` admit, in MiB.
pub const MEMORY_MIB_RANGE: std::ops::RangeInclusive<u64> = 64..=1 << 24;

/// Pipeline-wide resource limits.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Limits {
    pub texture: crate::texture::TextureLimits,
    /// The process's memory budget in bytes (`limits: (memory_mib: …)`); `None`: the default,
    /// half the machine's memory (see `memory::process_budget`).
    pub memory: Option<u64>,
}

impl PipelineConfig {
    pub fn source_dir(&self) -> PathBuf {
        self.root.join(&self.source)
    }

    pub fn output_dir(&self) -> PathBuf {
        self.root.join(&self.output)
    }

    /// The local stage cache: `<output>/.cirrus/cache`.
    pub fn cache_dir(&self) -> PathBuf {
        self.output_dir().join(".cirrus").join("cache")
    }

    /// The asset that a source file (relative to the source folder) becomes under `rules`,
    /// unless an explicit asset already uses it.
    pub fn asset_for_rule_match(&self, relative: &Path) -> Option<AssetConfig> {
        if self.assets.iter().any(|asset| asset.source.main_file() == relative) {
            return None;
        }
        self.rule_asset(relative)
    }

    /// The asset that the first rule matching `relative` makes of it, whether or not an explicit
    /// asset uses the file (the driver, which lists thousands, checks that once for all).
    pub fn rule_asset(&self, relative: &Path) -> Option<AssetConfig> {
        let rule = self.rules.iter().find(|rule| rule.matcher.is_match(relative))?;
        let name = crate::diagnostic::display_path(&relative.with_extension(""));
        let source = AssetSource::of_file(rule.kind, relative);
        Some(AssetConfig { name, source, settings: rule.settings.clone() })
    }
}

/// Reading or validating `pipeline.ron` failed; every problem found is listed.
#[derive(Debug, thiserror::Error)]
#[error("{}", .diagnostics.iter().map(|d| d.to_string()).collect::<Vec<_>>().join("\n"))]
pub struct ConfigError {
    pub diagnostics: Vec<Diagnostic>,
}

/// The serde mirror of `pipeline.ron`: exactly what the file says, nothing resolved.
mod raw;

/// What an asset may be called, and which names share a folder.
mod asset_names;
pub use asset_names::reserved_asset_name;
use asset_names::valid_asset_name;
pub use asset_names::AssetFolders;

/// A glob over paths relative to the source folder (`*` stops at `/`, `**` crosses folders).
pub fn source_glob(glob: &str) -> Result<globset::GlobMatcher, String> {
    // A glob matches paths inside the source folder: one that climbs out or starts at the root
    // could never match, and used to fail later as "no texture matches".
    let climbs = glob.split(['/', '\\']).any(|part| part == "..");
    if climbs || glob.starts_with(['/', '\\']) || glob.as_bytes().get(1) == Some(&b':') {
        return Err(format!(
            "`{glob}` leads outside the source folder: globs are relative to `source` and stay inside it"
        ));
    }
    globset::GlobBuilder::new(glob)
        .literal_separator(true)
        .build()
        .map(|glob| glob.compile_matcher())
        .map_err(|error| error.kind().to_string())
}

/// Largest `pipeline.ron` read.
const MAX_PIPELINE_BYTES: u64 = 16 << 20;

/// Reads and validates `pipeline.ron` at `file` with the entries of `Kinds`, then checks on disk
/// that the output folder, with symbolic links resolved, neither holds nor lies inside the
/// source folder.
pub fn load_pipeline_with<Kinds: EntryKinds>(file: &Path) -> Result<PipelineConfig, ConfigError> {
    let fail = |message: String| ConfigError { diagnostics: vec![Diagnostic::new(file, message)] };
    let bytes = crate::files::read_regular_file(file, MAX_PIPELINE_BYTES).map_err(|why| {
        // "is not a regular file", "is larger than …" read as a sentence; the rest are reasons.
        fail(if why.is_predicate() {
            format!("the pipeline file {why}")
        } else {
            format!("cannot read the pipeline file: {why}")
        })
    })?;
    let text = String::from_utf8(bytes).map_err(|error| {
        let position =
            TextPosition::of_byte_offset(&String::from_utf8_lossy(error.as_bytes()), error.utf8_error().valid_up_to());
        ConfigError { diagnostics: vec![Diagnostic::at(file, position, "the pipeline file is not UTF-8 text")] }
    })?;
    let config = parse_pipeline_with::<Kinds>(file, &text)?;
    let (source, output) =
        (resolve_existing_prefix(&config.source_dir()), resolve_existing_prefix(&config.output_dir()));
    if let Some(overlap) = folder_overlap(&source, &output) {
        let position = find_key(&text, "output").map(|offset| TextPosition::of_byte_offset(&text, offset));
        let message = format!(
            "{overlap} (after following symbolic links: source {}, output {})",
            source.display(),
            output.display()
        );
        return Err(ConfigError {
            diagnostics: vec![match position {
                Some(position) => Diagnostic::at(file, position, message),
                None => Diagnostic::new(file, message),
            }],
        });
    }
    Ok(config)
}

/// `path` made absolute with symbolic links resolved as far as it exists (an output folder
/// may not exist yet: its missing tail is appended to its nearest existing ancestor, resolved).
fn resolve_existing_prefix(path: &Path) -> PathBuf {
    let absolute = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut existing = absolute.as_path();
    let mut tail = Vec::new();
    loop {
        if let Ok(resolved) = existing.canonicalize() {
            return tail.iter().rev().fold(resolved, |path: PathBuf, part| path.join(part));
        }
        match (existing.parent(), existing.file_name()) {
            (Some(parent), Some(name)) => {
                tail.push(name.to_os_string());
                existing = parent;
            }
            _ => return absolute,
        }
    }
}

/// Why an output folder may not be used beside this source folder, if it may not: artifacts
/// and previews written there would overwrite source files, and the watcher would bake its own
/// output.
fn folder_overlap(source: &Path, output: &Path) -> Option<&'static str> {
    if output == source {
        Some("the output folder must not be the source folder")
    } else if source.starts_with(output) {
        Some("the output folder must not contain the source folder")
    } else if output.starts_with(source) {
        Some("the output folder must not lie inside the source folder")
    } else {
        None
    }
}

/// Parses and validates the text of a `pipeline.ron` that lives at `file`, with the entries of
/// `Kinds`.
pub fn parse_pipeline_with<Kinds: EntryKinds>(file: &Path, text: &str) -> Result<PipelineConfig, ConfigError> {
    // Editors on Windows may save a byte-order mark.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let validation = Validation {
        file,
        text,
        kinds: Kinds::KINDS,
        limits: Limits::default(),
        encode: EncodeSettings::default(),
        diagnostics: Vec::new(),
    };
    let raw: raw::Pipeline<Kinds::Entry, Kinds::KindName> =
        validation.read().map_err(|diagnostic| ConfigError { diagnostics: vec![diagnostic] })?;
    let root = file.parent().map(Path::to_path_buf).unwrap_or_default();
    let root = if root.as_os_str().is_empty() { PathBuf::from(".") } else { root };
    validation.validate::<Kinds>(raw, root)
}

/// The options every reading of `pipeline.ron` takes: `Some` implicit, and an entry written as
/// its kind's fields (`Material(name: …)`, the kind's `Entry` struct in the variant).
fn ron_options() -> ron::Options {
    use ron::extensions::Extensions;
    ron::Options::default().with_default_extension(Extensions::IMPLICIT_SOME | Extensions::UNWRAP_VARIANT_NEWTYPES)
}

/// What a RON error means to the person who wrote the file: an unknown kind or field with the
/// closest known one, and other errors with the field whose value they are in (RON says only
/// "Expected comma" of `max_size: 2048.0`).
fn ron_message(error: &ron::error::SpannedError, text: &str, kinds: &[KindFields]) -> String {
    use crate::diagnostic::did_you_mean;
    let list = |names: &[&str]| names.iter().map(|name| format!("`{name}`")).collect::<Vec<_>>().join(", ");
    match &error.code {
        ron::Error::NoSuchEnumVariant { expected, found, outer } => {
            let what = if outer.as_deref() == Some("Asset") {
                "asset kind".to_string()
            } else {
                format!("`{}` value", outer.as_deref().unwrap_or("enum"))
            };
            format!(
                "unknown {what} `{found}`{}; expected one of {}",
                did_you_mean(found, expected.iter().copied()),
                list(expected)
            )
        }
        ron::Error::NoSuchStructField { expected, found, outer }
            if kinds.iter().any(|kind| Some(kind.kind.name()) == outer.as_deref()) =>
        {
            // A settings section of another kind: said with the kinds that read it.
            let kind = outer.as_deref().unwrap_or_default();
            let readers: Vec<&str> = kinds
                .iter()
                .filter(|other| other.fields.contains(&found.as_str()))
                .map(|other| other.kind.name())
                .collect();
            match readers.as_slice() {
                [_, ..] => format!(
                    "a {kind} asset does not read `{found}` settings (only {} assets do); its fields are {}",
                    readers.join(" and "),
                    list(expected)
                ),
                [] => format!(
                    "unknown field `{found}` in a {kind} asset{}; expected one of {}",
                    did_you_mean(found, expected.iter().copied()),
                    list(expected)
                ),
            }
        }
        ron::Error::NoSuchStructField { expected, found, outer } => {
            let outer = outer.as_deref().map_or("this structure".to_string(), |outer| {
                format!("`{}`", outer.trim_end_matches("Overrides").trim_start_matches("Raw").to_lowercase())
            });
            format!(
                "unknown field `{found}` in {outer}{}; expected one of {}",
                did_you_mean(found, expected.iter().copied()),
                list(expected)
            )
        }
        ron::Error::MissingStructField { field, outer } => {
            let outer = outer.as_deref().map_or("this structure".to_string(), |outer| format!("`{outer}`"));
            format!("{outer} needs the field `{field}`")
        }
        // Errors in a value: said with the field the value is for.
        code @ (ron::Error::ExpectedComma
        | ron::Error::ExpectedFloat
        | ron::Error::ExpectedInteger
        | ron::Error::ExpectedBoolean
        | ron::Error::ExpectedString
        | ron::Error::ExpectedArray
        | ron::Error::ExpectedStructLike
        | ron::Error::ExpectedOption
        | ron::Error::IntegerOutOfBounds) => {
            let offset = byte_offset(text, error.position.line, error.position.col);
            match field_before(text, offset) {
                Some((field, value)) => {
                    let hint = match code {
                        ron::Error::ExpectedComma
                            if text[offset..].starts_with('.') && value.bytes().all(|byte| byte.is_ascii_digit()) =>
                        {
                            ": it takes a whole number"
                        }
                        ron::Error::ExpectedFloat | ron::Error::ExpectedInteger if text[offset..].starts_with('"') => {
                            ": write the number without quotes"
                        }
                        _ => "",
                    };
                    format!("in `{field}`: {}{hint}", code.to_string().to_lowercase())
                }
                None => code.to_string(),
            }
        }
        code => code.to_string(),
    }
}

/// The byte offset of a 1-based line and (character) column.
fn byte_offset(text: &str, line: usize, column: usize) -> usize {
    let line_start: usize = text.split_inclusive('\n').take(line.saturating_sub(1)).map(str::len).sum();
    let rest = &text[line_start.min(text.len())..];
    line_start + rest.char_indices().nth(column.saturating_sub(1)).map_or(rest.len(), |(index, _)| index)
}

/// The field whose value runs up to `offset` (`name: value` with no separator or bracket in
/// between), and the value written so far.
fn field_before(text: &str, offset: usize) -> Option<(&str, &str)> {
    let before = &text[..offset.min(text.len())];
    let colon = before.rfind(':')?;
    let value = before[colon + 1..].trim();
    if value.contains([',', '(', ')', '[', ']', '{', '}', ':']) {
        return None;
    }
    let name_part = before[..colon].trim_end();
    let start = name_part
        .char_indices()
        .rev()
        .find(|(_, character)| !(character.is_alphanumeric() || *character == '_'))
        .map_or(0, |(index, character)| index + character.len_utf8());
    let name = &name_part[start..];
    (!name.is_empty() && !name.starts_with(|character: char| character.is_ascii_digit())).then_some((name, value))
}

/// The reading of one `pipeline.ron`: its text, the kinds' fields, what is resolved so far that
/// entries are checked against, and every problem found.
pub struct Validation<'text> {
    file: &'text Path,
    text: &'text str,
    kinds: &'static [KindFields],
    limits: Limits,
    /// `defaults:`'s `encode` section, resolved.
    encode: EncodeSettings,
    diagnostics: Vec<Diagnostic>,
}

impl sections::Check for Validation<'_> {
    fn error_at_key(&mut self, key: &str, anchor: usize, message: &str) {
        Validation::error_at_key(self, key, anchor, message);
    }
}

impl Validation<'_> {
    /// The whole text read as `T` (a diagnostic at ron's position, said for people).
    fn read<T: serde::de::DeserializeOwned>(&self) -> Result<T, Diagnostic> {
        ron_options().from_str(self.text).map_err(|error| {
            let position = TextPosition { line: error.position.line as u32, column: error.position.col as u32 };
            Diagnostic::at(self.file, position, ron_message(&error, self.text, self.kinds))
        })
    }

    fn push_unique(&mut self, diagnostic: Diagnostic) {
        // Two kinds reading one section (the alpha test) find its problems twice.
        if !self.diagnostics.contains(&diagnostic) {
            self.diagnostics.push(diagnostic);
        }
    }

    /// Kind `K`'s settings from its sections of `defaults:` (one more reading of the text).
    pub fn kind_defaults<K: KindEntry>(&mut self) -> KindSettings {
        let written = match self.read::<raw::KindDefaults<K::Defaults>>() {
            Ok(read) => read.defaults,
            Err(diagnostic) => {
                self.push_unique(diagnostic);
                K::Defaults::default()
            }
        };
        let before = self.diagnostics.len();
        let settings = K::defaults(&written, self);
        for diagnostic in self.diagnostics.split_off(before) {
            self.push_unique(diagnostic);
        }
        KindSettings::new(settings)
    }

    /// One entry of kind `K`: its name (valid, not reserved, not colliding with `names`), its
    /// `encode` over the defaults', its source and settings over `defaults` (its kind's).
    pub fn resolve_entry<K: KindEntry>(
        &mut self,
        entry: &K::Entry,
        defaults: &[KindSettings],
        names: &mut AssetFolders,
    ) -> Option<AssetConfig> {
        let (name, encode_written) = K::name_and_encode(entry);
        let anchor = self.offset_of_value(name, 0).unwrap_or(0);
        self.check_asset_name(name, anchor, names);
        let kind_defaults = defaults.iter().find_map(KindSettings::downcast::<K>)?;
        let name = name.to_string();
        let kind = self.kinds.iter().find(|fields| fields.kind.name() == K::NAME).expect("a listed kind").kind;
        let mut check = EntryCheck { check: self, anchor, name: &name, kind };
        let (source, own) = K::resolve(entry, kind_defaults, &mut check)?;
        let mut encode = self.encode.clone();
        merge_encode(self, &mut encode, encode_written, anchor);
        Some(AssetConfig { name: name.clone(), source, settings: Settings { encode, kind: KindSettings::new(own) } })
    }

    fn validate<Kinds: EntryKinds>(
        mut self,
        raw: raw::Pipeline<Kinds::Entry, Kinds::KindName>,
        root: PathBuf,
    ) -> Result<PipelineConfig, ConfigError> {
        let raw_rules: Vec<raw::Rule<AssetKind>> =
            raw.rules.iter().map(|rule| raw::Rule { glob: rule.glob.clone(), kind: rule.kind.into() }).collect();
        let source = self.project_path(&raw.source, "source", 0);
        let output = self.project_path(&raw.output, "output", 0);
        if let Some(overlap) =
            source.as_ref().zip(output.as_ref()).and_then(|(source, output)| folder_overlap(source, output))
        {
            self.error_at_value(&raw.output, 0, overlap);
        }
        let (source, output) = (source.unwrap_or_default(), output.unwrap_or_default());
        let server = raw.server.as_ref().and_then(|address| match resolve_socket_address(address) {
            Ok(address) => Some(address),
            Err(why) => {
                self.error_at_value(address, 0, &why);
                None
            }
        });
        if let Some(mib) = raw.limits.texture_memory_mib {
            if !(16..=1 << 24).contains(&mib) {
                self.error_at_key("texture_memory_mib", 0, "texture_memory_mib must be between 16 and 16777216 (MiB)");
            }
            self.limits.texture.working_set = mib << 20;
        }
        if let Some(mib) = raw.limits.memory_mib {
            if !(MEMORY_MIB_RANGE).contains(&mib) {
                self.error_at_key("memory_mib", 0, "memory_mib must be between 64 and 16777216 (MiB)");
            }
            self.limits.memory = Some(mib << 20);
        }
        let remote_cache =
            raw.cache.remote.as_ref().and_then(|url| match crate::cache::remote::parse_remote_url(url) {
                Ok(location) => Some(crate::cache::remote::RemoteCacheSettings {
                    url: url.clone(),
                    location,
                    mode: raw.cache.mode.unwrap_or_default(),
                }),
                Err(why) => {
                    self.error_at_value(url, 0, &why);
                    None
                }
            });

        self.check_default_sections(&raw.defaults.sections);
        let mut encode = EncodeSettings::default();
        merge_encode(&mut self, &mut encode, &raw.defaults.encode, 0);
        self.encode = encode;
        let defaults = Kinds::defaults(&mut self);

        let mut assets = Vec::new();
        let mut names = AssetFolders::default();
        for entry in &raw.assets {
            if let Some(config) = Kinds::resolve(&mut self, entry, &defaults, &mut names) {
                assets.push(config);
            }
        }

        self.check_asset_references(&assets, &raw_rules);

        let mut rules = Vec::new();
        for rule in &raw_rules {
            let refusal = self.kinds.iter().find(|kind| kind.kind == rule.kind).and_then(|kind| kind.rule_refusal);
            if let Some(refusal) = refusal {
                self.error_at_value(&rule.glob, 0, &format!("a rule makes one asset per file: {refusal}"));
            }
            let Some(own) = defaults.iter().find(|settings| settings.kind_name() == rule.kind.name()) else { continue };
            let settings = Settings { encode: self.encode.clone(), kind: own.clone() };
            match source_glob(&rule.glob) {
                Ok(matcher) => rules.push(Rule { glob: rule.glob.clone(), matcher, kind: rule.kind, settings }),
                Err(error) => self.error_at_value(&rule.glob, 0, &format!("bad glob: {error}")),
            }
        }

        if self.diagnostics.is_empty() {
            Ok(PipelineConfig {
                file: self.file.to_path_buf(),
                root,
                source,
                output,
                server,
                assets,
                rules,
                limits: self.limits,
                remote_cache,
            })
        } else {
            Err(ConfigError { diagnostics: self.diagnostics })
        }
    }

    /// Each section of `defaults:` is `encode` or one some kind reads.
    fn check_default_sections(&mut self, sections: &[String]) {
        let mut known: Vec<&str> = vec!["encode"];
        for name in self.kinds.iter().flat_map(|kind| kind.defaults) {
            if !known.contains(name) {
                known.push(name);
            }
        }
        for section in sections {
            if !known.contains(&section.as_str()) {
                let list = known.iter().map(|name| format!("`{name}`")).collect::<Vec<_>>().join(", ");
                let message = format!(
                    "unknown field `{section}` in `defaults`{}; expected one of {list}",
                    crate::diagnostic::did_you_mean(section, known.iter().copied())
                );
                let from = find_key(self.text, "defaults").unwrap_or(0);
                self.error_at_key(section, from, &message);
            }
        }
    }

    /// An asset's name: valid, in its normal form, not reserved, and sharing no folder with an
    /// asset listed before it (`names`, which it joins).
    fn check_asset_name(&mut self, name: &str, anchor: usize, names: &mut AssetFolders) {
        let normal_form = normalize_relative_path(Path::new(name)).map(|path| crate::diagnostic::display_path(&path));
        if valid_asset_name(&name.replace("//", "/").replace("/./", "/")) && normal_form.as_deref() != Some(name) {
            let normal_form = normal_form.unwrap_or_default();
            self.error_at_value(
                name,
                0,
                &format!("asset name `{name}` names the folder `{normal_form}`: write `{normal_form}`"),
            );
        } else if !valid_asset_name(name) {
            self.error_at_value(
                name,
                0,
                &format!("asset name `{name}` must be non-empty and use only letters, digits, `_`, `-`, `.` and `/`"),
            );
        }
        if let Some(reserved) = reserved_asset_name(name) {
            self.error_at_value(name, 0, &reserved);
        }
        let collision = names.collision(name).map(str::to_string);
        names.insert(name);
        if collision.as_deref() == Some(name) {
            let second = self.offset_of_value(name, anchor + name.len() + 2).unwrap_or(anchor);
            self.error_at_value(name, second, &format!("asset name `{name}` is used twice"));
        } else if let Some(other) = collision {
            self.error_at_value(
                name,
                anchor,
                &format!("asset names `{other}` and `{name}` would share a folder: one lies inside the other"),
            );
        }
    }

    /// Each asset another's settings name (a Material's `ao_source`) is of the kind they must
    /// be: a listed one, or (when a rule makes assets of that kind, whose names are known only
    /// once files are listed) any name that is not a listed asset of another kind; the build
    /// reports a name no asset has.
    fn check_asset_references(&mut self, assets: &[AssetConfig], rules: &[raw::Rule<AssetKind>]) {
        for asset in assets {
            let Some(reference) = asset.settings.kind.reference() else { continue };
            let (name, field, source, wanted) = (&asset.name, reference.field, reference.asset, reference.kind);
            let rules_make_it = rules.iter().any(|rule| rule.kind.name() == wanted);
            let message = match assets.iter().find(|other| other.name == source).map(|other| other.source.kind().name())
            {
                Some(kind) if kind == wanted => continue,
                Some(kind) => {
                    format!("asset `{name}`: {field} `{source}` is a {kind} asset; it must name an {wanted} asset")
                }
                None if rules_make_it => continue,
                None => format!("asset `{name}`: {field} `{source}` names no asset of the pipeline"),
            };
            let anchor = self.offset_of_value(name, 0).unwrap_or(0);
            self.error_at_value(source, anchor, &message);
        }
    }

    /// A path relative to the project folder that must stay inside it.
    fn project_path(&mut self, value: &str, what: &str, anchor: usize) -> Option<PathBuf> {
        match normalize_relative_path(Path::new(value)) {
            Some(path) => Some(path),
            None => {
                self.error_at_value(
                    value,
                    anchor,
                    &format!(
                        "the {what} path `{value}` must be relative and stay inside the folder of the pipeline file"
                    ),
                );
                None
            }
        }
    }

    /// A path relative to the source folder that must stay inside it.
    fn source_path(&mut self, value: &str, anchor: usize) -> Option<PathBuf> {
        match normalize_relative_path(Path::new(value)) {
            Some(path) if !path.as_os_str().is_empty() => Some(path),
            _ => {
                self.error_at_value(
                    value,
                    anchor,
                    &format!("the asset path `{value}` must be a relative file path inside the source folder"),
                );
                None
            }
        }
    }

    fn offset_of_value(&self, value: &str, from: usize) -> Option<usize> {
        let quoted = format!("\"{value}\"");
        self.text.get(from..)?.find(&quoted).map(|index| index + from)
    }

    fn error_at_value(&mut self, value: &str, from: usize, message: &str) {
        let offset = self.offset_of_value(value, from);
        self.push(offset, message);
    }

    fn error_at_key(&mut self, key: &str, from: usize, message: &str) {
        let offset = self.text.get(from..).and_then(|rest| find_key(rest, key)).map(|index| index + from);
        self.push(offset, message);
    }

    fn push(&mut self, offset: Option<usize>, message: &str) {
        let diagnostic = match offset {
            Some(offset) => Diagnostic::at(self.file, TextPosition::of_byte_offset(self.text, offset), message),
            None => Diagnostic::new(self.file, message),
        };
        self.diagnostics.push(diagnostic);
    }
}

/// A listening address: `127.0.0.1:7878`, `[::1]:7878` or a host name with a port
/// (`localhost:7878`, resolved now; IPv4 preferred).
pub fn resolve_socket_address(text: &str) -> Result<SocketAddr, String> {
    use std::net::ToSocketAddrs;
    if let Ok(address) = text.parse::<SocketAddr>() {
        return Ok(address);
    }
    let usage = format!("`{text}` is not an address like 127.0.0.1:7878 or localhost:7878");
    if text.rsplit_once(':').is_none_or(|(host, port)| host.is_empty() || port.parse::<u16>().is_err()) {
        return Err(usage);
    }
    let addresses: Vec<SocketAddr> = text.to_socket_addrs().map_err(|error| format!("{usage}: {error}"))?.collect();
    addresses.iter().find(|address| address.is_ipv4()).or(addresses.first()).copied().ok_or(usage)
}

/// The offset of `key:` as a field name in `text` (not as a substring of another name).
fn find_key(text: &str, key: &str) -> Option<usize> {
    let bytes = text.as_bytes();
    let mut start = 0;
    while let Some(found) = text[start..].find(key) {
        let index = start + found;
        let before_ok = index == 0 || !(bytes[index - 1].is_ascii_alphanumeric() || bytes[index - 1] == b'_');
        let after = text[index + key.len()..].trim_start();
        if before_ok && after.starts_with(':') {
            return Some(index);
        }
        start = index + key.len();
    }
    None
}
