//! Output paths checked before any work: the file name and extension, the parent directory
//! (it exists and takes a new file), not an existing directory, and never one of the inputs
//! (the same path, a hard link to it, or a symbolic link to it).

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};

use scanflow::fs::atomic;

/// The extension of the meshes and point clouds scanflow writes.
pub const PLY: &str = "ply";

/// Check that `path` (the value of `-o`) can receive a new file in the format of `ext`.
pub fn output_file(path: &Path, ext: &str) -> Result<()> {
    output_file_as("-o", path, &[ext], "binary PLY")
}

/// Check that `path` (the value of `opt`) can receive a new file named with one of `exts`,
/// holding `format`.
pub fn output_file_as(opt: &str, path: &Path, exts: &[&str], format: &str) -> Result<()> {
    let shown = path.display();
    if path.file_name().is_none() {
        bail!("{opt} {shown}: expected a file name");
    }
    let got = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    if !exts.iter().any(|e| got.eq_ignore_ascii_case(e)) {
        bail!(
            "{opt} {shown}: scanflow writes {format} here; name the output *.{} (other formats are not written)",
            exts.join(" or *.")
        );
    }
    if path.is_dir() {
        bail!("{opt} {shown}: is a directory; expected a file name");
    }
    writable_parent(path)
}

/// Check that `-o path` can be a directory to write into: a directory, or nothing yet in an
/// existing directory.
pub fn output_dir(path: &Path) -> Result<()> {
    if path.exists() && !path.is_dir() {
        bail!("-o {}: exists and is not a directory", path.display());
    }
    if !parent(path).is_dir() {
        bail!(
            "-o {}: directory {} does not exist",
            path.display(),
            parent(path).display()
        );
    }
    Ok(())
}

/// Check that the directory `path` does not exist yet and that its parent takes it.
pub fn new_dir(path: &Path) -> Result<()> {
    if path.file_name().is_none() {
        bail!("-o {}: expected a directory name", path.display());
    }
    if std::fs::symlink_metadata(path).is_ok() {
        bail!(
            "-o {}: already exists; scanflow does not replace it (remove it or choose another name)",
            path.display()
        );
    }
    writable_parent(path)
}

/// The directory `path` goes into.
pub fn parent(path: &Path) -> PathBuf {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// Check that `path`'s parent directory exists and that a file can be created in it, by
/// creating and removing the temporary name the output will be written under.
pub fn writable_parent(path: &Path) -> Result<()> {
    let dir = parent(path);
    if dir.exists() && !dir.is_dir() {
        bail!(
            "-o {}: {} is not a directory",
            path.display(),
            dir.display()
        );
    }
    if !dir.is_dir() {
        bail!(
            "-o {}: directory {} does not exist",
            path.display(),
            dir.display()
        );
    }
    let probe = atomic::temp_name(path);
    let made = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe);
    match made {
        Ok(f) => {
            drop(f);
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => bail!(
            "-o {}: cannot create files in {}: {e}",
            path.display(),
            dir.display()
        ),
    }
}

/// Refuse an `output` that is one of `inputs` (same path, hard link or symbolic link), or
/// lies inside an input directory (a store).
pub fn not_an_input(output: &Path, inputs: &[&Path]) -> Result<()> {
    not_an_input_as("-o", output, inputs)
}

/// [`not_an_input`] for the output given by option `opt`.
pub fn not_an_input_as(opt: &str, output: &Path, inputs: &[&Path]) -> Result<()> {
    for input in inputs {
        if same_file(output, input) {
            bail!(
                "{opt} {}: is the input {}; scanflow never overwrites its inputs",
                output.display(),
                input.display()
            );
        }
        if input.is_dir() && inside(output, input) {
            bail!(
                "{opt} {}: lies inside the input {}; scanflow never writes into its inputs",
                output.display(),
                input.display()
            );
        }
    }
    Ok(())
}

/// Whether `a` and `b` name the same file (device and inode, links followed).
pub fn same_file(a: &Path, b: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (std::fs::metadata(a), std::fs::metadata(b)) {
            (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
            (Ok(x), Ok(y)) => x == y,
            _ => false,
        }
    }
}

/// Whether `path` (which need not exist) lies inside the existing directory `dir`.
pub fn inside(path: &Path, dir: &Path) -> bool {
    let Ok(dir) = std::fs::canonicalize(dir) else {
        return false;
    };
    let full = std::fs::canonicalize(path).or_else(|_| {
        let name = path.file_name().unwrap_or_default();
        std::fs::canonicalize(parent(path)).map(|p| p.join(name))
    });
    full.map(|p| p.starts_with(&dir) && p != dir)
        .unwrap_or(false)
}
