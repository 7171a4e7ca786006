// The one lookup of the team's shared data folder (the folder holding `problems/` and
// `data/`). No module-level attributes or imports beyond std: `build.rs` includes this file.

/// The shared data folder: `$MTPCR_SHARED_DIR` when set (whether or not it holds the data:
/// an explicit choice is not second-guessed), else the nearest `shared/` folder holding
/// `problems/` and `data/` in `start` or one of its ancestors.
pub fn find_shared_dir_from(start: &std::path::Path) -> Option<std::path::PathBuf> {
    if let Some(dir) = std::env::var_os("MTPCR_SHARED_DIR") {
        let dir = std::path::PathBuf::from(dir);
        return is_shared_dir(&dir).then_some(dir);
    }
    start
        .ancestors()
        .map(|a| a.join("shared"))
        .find(|d| is_shared_dir(d))
}

/// [`find_shared_dir_from`] the current directory.
pub fn find_shared_dir() -> Option<std::path::PathBuf> {
    let cwd = std::env::current_dir().ok()?;
    find_shared_dir_from(&cwd)
}

/// Does `dir` hold `problems/` and `data/`?
pub fn is_shared_dir(dir: &std::path::Path) -> bool {
    dir.join("problems").is_dir() && dir.join("data").is_dir()
}
