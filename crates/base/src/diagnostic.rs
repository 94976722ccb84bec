//! Diagnostics: a problem with an input, carrying the file and, where the format has them, the
//! line and column. Every stage reports bad input as a `Diagnostic`, never as a panic.

use std::fmt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// A position in a text file, 1-based.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct TextPosition {
    pub line: u32,
    pub column: u32,
}

impl TextPosition {
    /// The position of byte `offset` in `text` (1-based line and column, column in characters).
    pub fn of_byte_offset(text: &str, offset: usize) -> TextPosition {
        let offset = offset.min(text.len());
        let before = &text[..floor_char_boundary(text, offset)];
        let line = before.matches('\n').count() as u32 + 1;
        let line_start = before.rfind('\n').map_or(0, |index| index + 1);
        let column = before[line_start..].chars().count() as u32 + 1;
        TextPosition { line, column }
    }
}

fn floor_char_boundary(text: &str, mut offset: usize) -> usize {
    while offset > 0 && !text.is_char_boundary(offset) {
        offset -= 1;
    }
    offset
}

/// Whether a problem stops the bake (an error) or is only said (a warning: `cirrus check`'s
/// report of what the bake goes ahead past).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Severity {
    #[default]
    Error,
    Warning,
}

impl Severity {
    fn is_error(&self) -> bool {
        *self == Severity::Error
    }
}

/// One problem with one input file.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Diagnostic {
    /// The file at fault, relative to the project folder where it lies inside it.
    pub file: PathBuf,
    pub position: Option<TextPosition>,
    pub message: String,
    /// (Absent in stored diagnostics: an error.)
    #[serde(default, skip_serializing_if = "Severity::is_error")]
    pub severity: Severity,
}

impl Diagnostic {
    pub fn is_warning(&self) -> bool {
        self.severity == Severity::Warning
    }

    pub fn new(file: impl Into<PathBuf>, message: impl Into<String>) -> Diagnostic {
        Diagnostic { file: file.into(), position: None, message: message.into(), severity: Severity::Error }
    }

    pub fn at(file: impl Into<PathBuf>, position: TextPosition, message: impl Into<String>) -> Diagnostic {
        Diagnostic { file: file.into(), position: Some(position), message: message.into(), severity: Severity::Error }
    }

    /// The same problem, said as a warning.
    pub fn as_warning(&self) -> Diagnostic {
        Diagnostic { severity: Severity::Warning, ..self.clone() }
    }

    pub fn line(&self) -> Option<u32> {
        self.position.map(|position| position.line)
    }

    pub fn column(&self) -> Option<u32> {
        self.position.map(|position| position.column)
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", display_path(&self.file))?;
        if let Some(position) = self.position {
            write!(f, ":{}:{}", position.line, position.column)?;
        }
        match self.severity {
            Severity::Error => write!(f, ": {}", self.message),
            Severity::Warning => write!(f, ": warning: {}", self.message),
        }
    }
}

impl std::error::Error for Diagnostic {}

/// A path as users read it: forward slashes on every platform.
pub fn display_path(path: &Path) -> String {
    path.to_string_lossy().replace('\\', "/")
}

/// The candidate closest to `word` by edit distance (case-insensitive), when close enough to be
/// a slip (at most a third of the word's letters, and at least one): `BilboardCloud` →
/// `BillboardCloud`, `bush2.obj` → `bush_2.obj`.
pub fn closest<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let word_lower = word.to_lowercase();
    let limit = (word.chars().count() / 3).max(1);
    candidates
        .into_iter()
        .filter(|candidate| *candidate != word)
        .map(|candidate| (edit_distance(&word_lower, &candidate.to_lowercase()), candidate))
        .filter(|(distance, _)| *distance <= limit)
        .min_by_key(|(distance, _)| *distance)
        .map(|(_, candidate)| candidate)
}

/// ` (did you mean `X`?)` for the closest candidate, else nothing.
pub fn did_you_mean<'a>(word: &str, candidates: impl IntoIterator<Item = &'a str>) -> String {
    closest(word, candidates).map(|candidate| format!(" (did you mean `{candidate}`?)")).unwrap_or_default()
}

/// Levenshtein distance over characters.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, a_char) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, &b_char) in b.iter().enumerate() {
            let above = row[j + 1];
            row[j + 1] = (diagonal + usize::from(a_char != b_char)).min(row[j] + 1).min(above + 1);
            diagonal = above;
        }
    }
    row[b.len()]
}
