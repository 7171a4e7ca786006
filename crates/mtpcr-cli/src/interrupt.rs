//! Ctrl-C during `mtpcr register`: the run stops at once, removes the temporary files it was
//! writing, removes the results folder (and the parents it created) if this run created it
//! and nothing else is in it, prints `interrupted` and exits with code 130 (128 + SIGINT, as
//! shells report a process killed by Ctrl-C).
//!
//! Files are written under a temporary name and renamed into place while holding this
//! module's lock ([`writing`]), so the handler never runs halfway through a file: every file
//! of the folder is either complete or absent.

use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard, PoisonError};

/// Exit code of an interrupted run.
pub const EXIT_INTERRUPTED: u8 = 130;

/// The folder a run writes into, as the Ctrl-C handler must clean it.
struct Guarded {
    /// The results folder.
    dir: PathBuf,
    /// The folders this run created, the results folder first, then its new parents.
    created: Vec<PathBuf>,
}

static GUARDED: Mutex<Option<Guarded>> = Mutex::new(None);

fn lock() -> MutexGuard<'static, Option<Guarded>> {
    GUARDED.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Installs the Ctrl-C handler (once per process).
pub fn install() -> Result<(), String> {
    ctrlc::set_handler(on_interrupt).map_err(|e| format!("cannot install the Ctrl-C handler: {e}"))
}

/// From now on an interruption cleans `dir`; `created` lists the folders this run created
/// (the results folder first, then its new parents), which are removed if left empty.
pub fn guard(dir: &Path, created: Vec<PathBuf>) {
    *lock() = Some(Guarded {
        dir: dir.to_path_buf(),
        created,
    });
}

/// The results are written: an interruption no longer touches the folder.
pub fn release() {
    *lock() = None;
}

/// The run failed before writing: [`clean`]s the folder now and releases it.
pub fn discard(dir: &Path, created: &[PathBuf]) {
    let mut guarded = lock();
    clean(dir, created);
    *guarded = None;
}

/// Held while a file is written and renamed into place: an interruption waits for it.
pub struct WriteLock {
    _guard: MutexGuard<'static, Option<Guarded>>,
}

/// Takes the [`WriteLock`].
pub fn writing() -> WriteLock {
    WriteLock { _guard: lock() }
}

/// The temporary name under which `path` is written before being renamed into place:
/// `.NAME.PID.mtpcr-tmp` in the same folder (so the rename stays on one file system).
pub fn temporary_name(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "file".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(format!(".{name}.{}{TMP_SUFFIX}", std::process::id()))
}

const TMP_SUFFIX: &str = ".mtpcr-tmp";

/// Removes this process' temporary files from `dir`, then the folders this run created if
/// they are empty (the first one that is not stops the removal).
pub fn clean(dir: &Path, created: &[PathBuf]) {
    let ours = format!(".{}{TMP_SUFFIX}", std::process::id());
    if let Ok(entries) = std::fs::read_dir(dir) {
        for entry in entries.flatten() {
            if entry.file_name().to_string_lossy().ends_with(&ours) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
    for folder in created {
        if std::fs::remove_dir(folder).is_err() {
            break;
        }
    }
}

fn on_interrupt() {
    // Waits for a file being written to be complete; the lock is never released again.
    let guarded = lock();
    if let Some(g) = &*guarded {
        clean(&g.dir, &g.created);
    }
    use std::io::IsTerminal;
    if std::io::stderr().is_terminal() {
        // Start on a clean line, not after the progress bar.
        eprint!("\r\x1b[2K");
    }
    eprintln!("interrupted");
    std::process::exit(i32::from(EXIT_INTERRUPTED));
}
