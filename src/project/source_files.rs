//! Source files as the driver sees them: content hashes from the record's stamps or a read,
//! and the salsa inputs of the files an asset's kind reads.

use std::path::Path;

use salsa::Setter;

use super::{file_node_id, Project};
use crate::db::{FileContents, SourceFile};
use crate::record::FileStamp;
use crate::sources::read_source_stamped;

impl Project {
    /// Reads `paths` again now; true when any of them is new to the project or its bytes changed,
    /// or another input changed since the last finished build (so that a touch with identical
    /// bytes costs no build).
    pub fn refresh_sources<'a>(&mut self, paths: impl IntoIterator<Item = &'a Path>) -> bool {
        let mut changed = self.sources_changed_since_build;
        for path in paths {
            self.forget_asset_list_for(path);
            self.clean.unclean_readers_of(path);
            let before = self.last_known_hash(path);
            self.fresh.remove(path);
            let after = self.file_hash(path);
            changed |= before != Some(after);
        }
        changed
    }

    /// The content hash last seen of a file (its input's, or the record's), if any.
    pub(super) fn last_known_hash(&self, path: &Path) -> Option<Result<blake3::Hash, crate::files::ReadError>> {
        match self.files.get(path) {
            Some(file) => Some(file.contents(&self.db).as_ref().map(|contents| contents.hash).map_err(Clone::clone)),
            None => {
                self.known.get(path).cloned().or_else(|| self.skip.record().files.get(path).map(|file| Ok(file.hash)))
            }
        }
    }

    /// The content hash of a source file (or why it cannot be read): its input's when it has
    /// one, else the record's when the file's metadata did not move since it was recorded (not
    /// racy, no `--verify`), else read and hashed now (and recorded).
    pub(super) fn file_hash(&mut self, path: &Path) -> Result<blake3::Hash, crate::files::ReadError> {
        if self.files.contains_key(path) {
            let file = self.source_file(path);
            return file.contents(&self.db).as_ref().map(|contents| contents.hash).map_err(Clone::clone);
        }
        if self.fresh.contains(path) {
            if let Some(known) = self.known.get(path) {
                return known.clone();
            }
        }
        let seen_at = crate::record::now();
        if !self.options.verify {
            let trusted = FileStamp::read(&self.config.root.join(path))
                .and_then(|stamp| self.skip.trusted_hash(path, &stamp))
                .filter(|_| self.config.source_dir().is_dir());
            if let Some(hash) = trusted {
                self.fresh.insert(path.to_path_buf());
                self.known.insert(path.to_path_buf(), Ok(hash));
                return Ok(hash);
            }
        }
        self.files_read += 1;
        let recorded = self.skip.record().files.get(path).map(|file| file.hash);
        let read = read_source_stamped(&self.config.root, &self.config.source, path).map(|(contents, stamp)| {
            self.skip.remember_file(path, stamp, contents.hash, seen_at);
            contents
        });
        let hash = read.as_ref().map(|contents| contents.hash).map_err(Clone::clone);
        self.fresh.insert(path.to_path_buf());
        self.known.insert(path.to_path_buf(), hash.clone());
        // A file whose bytes changed is read again by the asset about to be baked: these bytes,
        // until the build ends (not those of a file merely touched).
        if hash.as_ref().ok() != recorded.as_ref() {
            self.unclaimed.insert(path.to_path_buf(), read);
        }
        hash
    }

    /// The salsa input of a file, read from disk now; set again only when its bytes changed.
    pub(super) fn source_file(&mut self, path: &Path) -> SourceFile {
        if self.fresh.contains(path) {
            if let Some(&file) = self.files.get(path) {
                // Bytes let go after an earlier group are read back for the stages about to run;
                // a file that changed meanwhile is read again as a new one.
                let readable = file
                    .contents(&self.db)
                    .as_ref()
                    .map_or(true, |contents| contents.bytes().is_ok() && !contents.read_back_failed());
                if readable {
                    return file;
                }
                self.fresh.remove(path);
            }
        }
        let contents = match self.unclaimed.remove(path).filter(|_| self.fresh.contains(path)) {
            Some(read) => read,
            None => {
                let seen_at = crate::record::now();
                self.files_read += 1;
                read_source_stamped(&self.config.root, &self.config.source, path).map(|(contents, stamp)| {
                    self.skip.remember_file(path, stamp, contents.hash, seen_at);
                    contents
                })
            }
        };
        self.fresh.insert(path.to_path_buf());
        match self.files.get(path) {
            Some(&file) => {
                // Equal bytes are set again where reading the last ones back failed: a stage that
                // asked meanwhile failed, and its memoized error must not outlive the file's return.
                let failed = file.contents(&self.db).as_ref().is_ok_and(FileContents::read_back_failed);
                if file.contents(&self.db) != &contents || failed {
                    let _previous = file.set_contents(&mut self.db).to(contents);
                    self.history.insert(file_node_id(path), (self.next_revision(), 0.0));
                    self.sources_changed_since_build = true;
                }
                file
            }
            None => {
                let file = SourceFile::new(&self.db, path.to_path_buf(), contents);
                self.history.insert(file_node_id(path), (self.next_revision(), 0.0));
                self.sources_changed_since_build = true;
                self.files.insert(path.to_path_buf(), file);
                file
            }
        }
    }
}
