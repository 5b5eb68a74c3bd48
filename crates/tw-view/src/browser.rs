//! The open dialog's model: a folder's sub-folders and the files terawalk can open (the
//! [`crate::opening::Opener`] says which), and the path field. Plain data, drawn by
//! [`crate::open_ui`].
//!
//! The dialog is the viewer's own, drawn with egui, not the system's: native dialog crates
//! (rfd and the like) need GTK or an XDG desktop portal, which Xvfb sessions, CI machines and
//! many servers viewing remote stores lack, and a dialog that cannot open there could not be
//! tested either.

use std::path::{Path, PathBuf};

/// One row of the listing.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub name: String,
    pub path: PathBuf,
    pub is_dir: bool,
    /// The file's size (0 for a folder).
    pub bytes: u64,
}

/// The open dialog's state.
#[derive(Clone, Debug, Default)]
pub struct FileBrowser {
    /// The folder listed.
    pub dir: PathBuf,
    /// The path field (a file or folder, absolute or relative to `dir`).
    pub path_text: String,
    pub entries: Vec<Entry>,
    /// Why the folder could not be listed.
    pub error: Option<String>,
}

/// What the path field's Enter (or a double click) asks for.
#[derive(Clone, Debug, PartialEq)]
pub enum Submit {
    /// Open this file.
    Open(PathBuf),
    /// The dialog moved into a folder.
    Entered,
    /// Nothing there: the dialog says why.
    Missing(String),
}

impl FileBrowser {
    /// The dialog over `dir`, listing what `accepts` takes.
    pub fn new(dir: &Path, accepts: &dyn Fn(&Path) -> bool) -> FileBrowser {
        let mut b = FileBrowser::default();
        b.enter(dir, accepts);
        b
    }

    /// Lists `dir` (a listing error is kept to be shown, with an empty list).
    pub fn enter(&mut self, dir: &Path, accepts: &dyn Fn(&Path) -> bool) {
        self.dir = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
        self.path_text.clear();
        match list(&self.dir, accepts) {
            Ok(entries) => {
                self.entries = entries;
                self.error = None;
            }
            Err(e) => {
                self.entries.clear();
                self.error = Some(format!("cannot list {}: {e}", self.dir.display()));
            }
        }
    }

    /// Goes to the parent folder (the root stays).
    pub fn parent(&mut self, accepts: &dyn Fn(&Path) -> bool) {
        if let Some(p) = self.dir.parent().map(Path::to_path_buf) {
            self.enter(&p, accepts);
        }
    }

    /// Enter in the path field: a folder is entered, a file is to be opened (whether terawalk
    /// reads it is the open's to say, with its error).
    pub fn submit(&mut self, accepts: &dyn Fn(&Path) -> bool) -> Submit {
        let text = self.path_text.trim();
        if text.is_empty() {
            return Submit::Missing("type a file or folder name".into());
        }
        let path = self.dir.join(text);
        self.activate(&path, accepts)
    }

    /// A double click on `path` (or Enter on it): a folder is entered, a file opened.
    pub fn activate(&mut self, path: &Path, accepts: &dyn Fn(&Path) -> bool) -> Submit {
        if path.is_dir() {
            self.enter(path, accepts);
            Submit::Entered
        } else if path.exists() {
            Submit::Open(path.to_path_buf())
        } else {
            Submit::Missing(format!("no file or folder {}", path.display()))
        }
    }
}

/// The folders of `dir` and the files `accepts` takes, folders first, each sorted by name;
/// hidden entries (names starting with a dot) are left out.
fn list(dir: &Path, accepts: &dyn Fn(&Path) -> bool) -> std::io::Result<Vec<Entry>> {
    let mut entries = Vec::new();
    for e in std::fs::read_dir(dir)?.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') {
            continue;
        }
        let path = e.path();
        // Followed through links: a link to a folder is a folder.
        let Ok(meta) = std::fs::metadata(&path) else { continue };
        if meta.is_dir() || accepts(&path) {
            let bytes = if meta.is_dir() { 0 } else { meta.len() };
            entries.push(Entry { name, path, is_dir: meta.is_dir(), bytes });
        }
    }
    entries.sort_by(|a, b| b.is_dir.cmp(&a.is_dir).then_with(|| a.name.cmp(&b.name)));
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ply_or_tw(p: &Path) -> bool {
        matches!(p.extension().and_then(|e| e.to_str()), Some("ply" | "tw"))
    }

    #[test]
    fn lists_folders_first_then_the_files_it_can_open() {
        let dir = tempfile::tempdir().unwrap();
        for f in ["b.ply", "a.tw", "notes.txt", ".hidden.ply"] {
            std::fs::write(dir.path().join(f), "x").unwrap();
        }
        std::fs::create_dir(dir.path().join("zeta")).unwrap();
        let b = FileBrowser::new(dir.path(), &ply_or_tw);
        let names: Vec<&str> = b.entries.iter().map(|e| e.name.as_str()).collect();
        assert_eq!(names, ["zeta", "a.tw", "b.ply"]);
        assert!(b.entries[0].is_dir && b.entries[1].bytes == 1);
        assert!(b.error.is_none());
    }

    #[test]
    fn enter_opens_files_and_enters_folders_and_says_what_is_missing() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("sub")).unwrap();
        std::fs::write(dir.path().join("sub").join("m.ply"), "x").unwrap();
        let mut b = FileBrowser::new(dir.path(), &ply_or_tw);
        b.path_text = "sub".into();
        assert_eq!(b.submit(&ply_or_tw), Submit::Entered);
        assert_eq!(b.entries.len(), 1);
        b.path_text = "m.ply".into();
        assert_eq!(b.submit(&ply_or_tw), Submit::Open(b.dir.join("m.ply")));
        b.path_text = "nothing.ply".into();
        assert!(matches!(b.submit(&ply_or_tw), Submit::Missing(m) if m.contains("nothing.ply")));
        b.parent(&ply_or_tw);
        assert_eq!(b.dir, std::fs::canonicalize(dir.path()).unwrap());
    }

    #[test]
    fn a_folder_that_cannot_be_listed_says_why() {
        let dir = tempfile::tempdir().unwrap();
        let b = FileBrowser::new(&dir.path().join("gone"), &ply_or_tw);
        assert!(b.entries.is_empty());
        assert!(b.error.as_deref().is_some_and(|e| e.contains("cannot list")), "{:?}", b.error);
    }
}
