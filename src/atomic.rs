//! Files written whole or not at all.
//!
//! Every file Lantern writes (rendered and exported images, scenes, the
//! previewer's session, the outputs of `validate` and `converge`, exported
//! grids) goes through [`write_atomically`]: the bytes go to a temporary
//! file beside the target (`.NAME.tmp-PID-N`, in the same folder so that
//! the final step is a rename within one file system), which is flushed,
//! synced and then renamed over the target. A failure at any step (a full
//! disk, a file-size limit, a vanished folder) removes the temporary file
//! and leaves the target exactly as it was; the error says so.
//!
//! A target that is a symbolic link is written through: the link is
//! followed to the file it names, which is replaced, so the link survives.
//!
//! [`check_writable`] tries the same steps with an empty probe file before
//! any long work starts, so that a missing or read-only output folder is
//! reported before a render rather than after it.
//!
//! This module is a leaf like `scene` and `physics`: it uses only `std`.

use std::fs::{File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Symbolic links followed at most when resolving a target (as Linux's
/// `MAXSYMLINKS`).
const MAX_LINKS: usize = 40;

/// A file could not be written; the previous file, if any, is unchanged.
#[derive(Debug, thiserror::Error)]
#[error("cannot write {}: {reason}; {}", path.display(), kept_text(path, *kept))]
pub struct WriteError {
    /// The file that was to be written (as given).
    pub path: PathBuf,
    /// What went wrong.
    pub reason: String,
    /// Whether a file existed at the target and was kept unchanged (else
    /// nothing was written there).
    pub kept: bool,
}

fn kept_text(path: &Path, kept: bool) -> String {
    if kept {
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| path.display().to_string());
        format!("the previous {name} was kept unchanged")
    } else {
        "no file was written".into()
    }
}

/// A counter that makes temporary names unique within the process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The file a write to `path` replaces: `path` itself, or for a symbolic
/// link the file it names (links followed up to `MAX_LINKS` deep; a
/// dangling link resolves to where it points).
pub fn resolve_target(path: &Path) -> io::Result<PathBuf> {
    let mut current = path.to_owned();
    for _ in 0..MAX_LINKS {
        match std::fs::symlink_metadata(&current) {
            Ok(meta) if meta.file_type().is_symlink() => {
                let link = std::fs::read_link(&current)?;
                current = if link.is_absolute() {
                    link
                } else {
                    current.parent().unwrap_or(Path::new("")).join(link)
                };
            }
            // Not a link, or nothing there yet: this is the file.
            _ => return Ok(current),
        }
    }
    Err(io::Error::other(format!(
        "more than {MAX_LINKS} levels of symbolic links"
    )))
}

/// The folder of `target` ("." for a bare file name).
fn folder_of(target: &Path) -> &Path {
    match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Creates a fresh temporary file beside `target`.
fn create_temp(target: &Path) -> io::Result<(PathBuf, File)> {
    let folder = folder_of(target);
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .ok_or_else(|| io::Error::other("the path does not name a file"))?;
    loop {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let temp = folder.join(format!(".{name}.tmp-{}-{n}", std::process::id()));
        match OpenOptions::new().write(true).create_new(true).open(&temp) {
            Ok(file) => return Ok((temp, file)),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
}

/// Checks before long work that `path` can be written: its folder exists
/// and is a folder, a file can be created there (an empty probe file is
/// created and removed), and the target is not a folder.
pub fn check_writable(path: &Path) -> Result<(), WriteError> {
    let fail = |reason: String| WriteError {
        path: path.to_owned(),
        reason,
        kept: path.exists(),
    };
    let target = resolve_target(path).map_err(|e| fail(e.to_string()))?;
    let folder = folder_of(&target);
    match std::fs::metadata(folder) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return Err(fail(format!("{} is not a folder", folder.display()))),
        Err(e) => {
            return Err(fail(format!(
                "the output folder {} does not exist or cannot be read ({e})",
                folder.display()
            )))
        }
    }
    if target.is_dir() {
        return Err(fail(format!("{} is a folder", target.display())));
    }
    let (temp, file) = create_temp(&target).map_err(|e| {
        fail(format!(
            "cannot create a file in the output folder {} ({e})",
            folder.display()
        ))
    })?;
    drop(file);
    let _ = std::fs::remove_file(&temp);
    Ok(())
}

/// Writes `path` whole or not at all: `write` fills a buffered temporary
/// file beside the target, which is then synced and renamed over it. On
/// any failure (of `write` or of the file system) the temporary file is
/// removed and the target is left as it was. A symbolic link at `path` is
/// followed (see [`resolve_target`]) and survives. The new file keeps the
/// permissions of the one it replaces.
pub fn write_atomically<E: std::fmt::Display>(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), E>,
) -> Result<(), WriteError> {
    let existed = path.exists();
    let fail = |reason: String| WriteError {
        path: path.to_owned(),
        reason,
        kept: existed,
    };
    let target = resolve_target(path).map_err(|e| fail(e.to_string()))?;
    if target.is_dir() {
        return Err(fail(format!("{} is a folder", target.display())));
    }
    let (temp, file) = create_temp(&target).map_err(|e| {
        fail(format!(
            "cannot create a temporary file in {} ({e})",
            folder_of(&target).display()
        ))
    })?;
    let result = fill(&target, file, write).and_then(|()| {
        std::fs::rename(&temp, &target).map_err(|e| format!("cannot rename the new file ({e})"))
    });
    match result {
        Ok(()) => {
            sync_folder(folder_of(&target));
            Ok(())
        }
        Err(reason) => {
            let _ = std::fs::remove_file(&temp);
            Err(fail(reason))
        }
    }
}

/// [`write_atomically`] of a byte string.
pub fn write_bytes(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    write_atomically(path, |w| w.write_all(bytes))
}

/// Runs `write` on the temporary file, flushes and syncs it, and gives it
/// the permissions of the file it replaces.
fn fill<E: std::fmt::Display>(
    target: &Path,
    file: File,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), E>,
) -> Result<(), String> {
    let mut out = BufWriter::new(file);
    write(&mut out).map_err(|e| e.to_string())?;
    let file = out.into_inner().map_err(|e| e.error().to_string())?;
    if let Ok(meta) = std::fs::metadata(target) {
        // Best effort: a file we may not re-mode is still written.
        let _ = file.set_permissions(meta.permissions());
    }
    file.sync_all().map_err(|e| e.to_string())
}

/// Syncs a folder so that a rename in it is durable (best effort: not
/// every platform or file system can open or sync a folder).
fn sync_folder(folder: &Path) {
    #[cfg(unix)]
    if let Ok(dir) = File::open(folder) {
        let _ = dir.sync_all();
    }
    #[cfg(not(unix))]
    let _ = folder;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leftovers(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".tmp-"))
            .collect()
    }

    #[test]
    fn writes_and_replaces() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        write_bytes(&p, b"one").unwrap();
        write_bytes(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert!(leftovers(dir.path()).is_empty());
    }

    /// A failing writer leaves the old file and no temporary file, and the
    /// message says the file was kept.
    #[test]
    fn failure_keeps_the_old_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.txt");
        std::fs::write(&p, b"old").unwrap();
        let e = write_atomically(&p, |w| {
            w.write_all(b"partial")?;
            Err(io::Error::other("disk full"))
        })
        .unwrap_err();
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert!(leftovers(dir.path()).is_empty());
        let text = e.to_string();
        assert!(
            text.contains("b.txt") && text.contains("disk full") && text.contains("kept"),
            "{text}"
        );
        let q = dir.path().join("new.txt");
        let e = write_atomically(&q, |_| Err("no")).unwrap_err();
        assert!(!q.exists());
        assert!(e.to_string().contains("no file was written"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn symbolic_links_survive() {
        let dir = tempfile::tempdir().unwrap();
        let real = dir.path().join("real.txt");
        std::fs::write(&real, b"old").unwrap();
        let link = dir.path().join("link.txt");
        std::os::unix::fs::symlink("real.txt", &link).unwrap();
        write_bytes(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink());
        assert_eq!(std::fs::read(&real).unwrap(), b"new");
    }

    #[test]
    fn missing_folder_is_reported_before_work() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("no/such/folder/x.exr");
        let e = check_writable(&p).unwrap_err().to_string();
        assert!(e.contains("does not exist") && e.contains("x.exr"), "{e}");
        assert!(check_writable(&dir.path().join("ok.exr")).is_ok());
        assert!(leftovers(dir.path()).is_empty());
        let e = check_writable(dir.path()).unwrap_err().to_string();
        assert!(e.contains("is a folder"), "{e}");
    }
}
