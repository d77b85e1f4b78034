//! Atomic file writing: write a temporary file beside the target, flush it, then rename it over
//! the target (and sync the folder), so a crash never leaves a half-written file.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Failure to write a file atomically; names the file.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {path}: {source}")]
pub struct WriteError {
    /// The file that was being written.
    pub path: PathBuf,
    /// What went wrong.
    #[source]
    pub source: std::io::Error,
}

/// Writes `bytes` to `path` atomically (temporary file in the same folder, fsync, rename, then
/// [`sync_dir`] on the folder).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    let wrap = |source| WriteError {
        path: path.to_path_buf(),
        source,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let file_name = path
        .file_name()
        .ok_or_else(|| wrap(std::io::Error::other("path has no file name")))?;
    let mut tmp_name = std::ffi::OsString::from(".");
    tmp_name.push(file_name);
    tmp_name.push(format!(".tmp{}", std::process::id()));
    let tmp_path = dir.join(tmp_name);
    let result = (|| {
        let mut file = std::fs::File::create(&tmp_path)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&tmp_path, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp_path);
    }
    result.map_err(wrap)?;
    sync_dir(&dir);
    Ok(())
}

/// Asks for a rename into `dir` to reach the disk: on Unix a folder's entries are made durable
/// by syncing the folder itself, so without this a crash soon after a save could bring back the
/// old file. Best effort: the file is already in place and whole, and some file systems refuse
/// to sync a folder, so a failure here is not reported. Does nothing where a folder cannot be
/// opened as a file.
pub fn sync_dir(dir: &Path) {
    #[cfg(unix)]
    if let Ok(folder) = std::fs::File::open(dir) {
        let _ = folder.sync_all();
    }
    #[cfg(not(unix))]
    let _ = dir;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_whole_file_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("a.txt");
        write_atomic(&path, b"first").expect("write");
        write_atomic(&path, b"second").expect("overwrite");
        assert_eq!(std::fs::read(&path).expect("read"), b"second");
        let entries: Vec<_> = std::fs::read_dir(dir.path()).expect("list").collect();
        assert_eq!(entries.len(), 1);
    }

    #[test]
    fn missing_folder_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("no/such/dir/a.txt");
        let err = write_atomic(&path, b"x").expect_err("must fail");
        assert!(err.to_string().contains("a.txt"));
    }
}
