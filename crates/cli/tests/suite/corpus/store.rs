//! The corpus's damaged stores: edited manifests and broken cell files.

use super::*;

/// Copy a store directory (and its `cells/`).
pub(super) fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let dst = to.join(e.file_name());
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dst);
        } else {
            std::fs::copy(e.path(), dst).unwrap();
        }
    }
}

/// A damage that edits a store's manifest.
pub(super) fn edit(f: impl Fn(&mut serde_json::Value)) -> impl Fn(&Path) -> PathBuf {
    move |st: &Path| {
        let mut m = manifest(st);
        f(&mut m);
        set_manifest(st, &m);
        st.to_path_buf()
    }
}

impl Corpus {
    /// A case on a copy of the store `base`, damaged by `damage`, which returns the file the
    /// message must name.
    fn store(
        &mut self,
        base: &Path,
        name: &str,
        cmd: Cmd,
        loc: &'static [&'static str],
        damage: &dyn Fn(&Path) -> PathBuf,
    ) {
        let st = self.dir(name).join(format!("{name}.store"));
        copy_dir(base, &st);
        let named = damage(&st);
        self.add_named(name, cmd, &st, &named, loc, None);
    }
}

/// Damaged manifests: refused when the store is opened.
pub(super) fn store_manifest_cases(c: &mut Corpus, base: &Path) {
    use Cmd::*;
    let dup = |m: &mut serde_json::Value| {
        let c1 = m["cells"][1].clone();
        m["cells"].as_array_mut().unwrap().insert(2, c1);
    };
    c.store(base, "store_duplicate_cell", Info, CELL, &edit(dup));
    c.store(
        base,
        "store_duplicate_cell_reconstruct",
        Reconstruct,
        CELL,
        &edit(dup),
    );
    c.store(
        base,
        "store_wrong_point_count",
        Info,
        NONE,
        &edit(|m| {
            m["point_count"] = (m["point_count"].as_u64().unwrap() * 2).into();
        }),
    );
    c.store(
        base,
        "store_wrong_cell_count",
        Verify,
        NONE,
        &edit(|m| {
            // Counts still adding up: only reading the cells finds the difference.
            let a = m["cells"][0]["count"].as_u64().unwrap();
            let b = m["cells"][1]["count"].as_u64().unwrap();
            m["cells"][0]["count"] = (a + 1).into();
            m["cells"][1]["count"] = (b - 1).into();
        }),
    );
    c.store(
        base,
        "store_escape_path",
        Info,
        CELL,
        &edit(|m| {
            m["cells"][0]["file"] = "../../../../etc/passwd".into();
        }),
    );
    c.store(
        base,
        "store_escape_path_reconstruct",
        Reconstruct,
        CELL,
        &edit(|m| {
            m["cells"][0]["file"] = "../../../../etc/passwd".into();
        }),
    );
    c.store(
        base,
        "store_absolute_path",
        Info,
        CELL,
        &edit(|m| {
            m["cells"][3]["file"] = "/etc/passwd".into();
        }),
    );
    c.store(
        base,
        "store_bad_key",
        Info,
        CELL,
        &edit(|m| m["cells"][0]["key"] = 0.into()),
    );
    c.store(
        base,
        "store_zero_count_cell",
        Info,
        CELL,
        &edit(|m| {
            let a = m["cells"][0]["count"].as_u64().unwrap();
            let b = m["cells"][1]["count"].as_u64().unwrap();
            m["cells"][0]["count"] = 0.into();
            m["cells"][1]["count"] = (a + b).into();
        }),
    );
    c.store(
        base,
        "store_huge_cell_count",
        Reconstruct,
        CELL,
        &edit(|m| {
            // Counts, total and inputs forged to agree on far more points than the file holds.
            let huge = 1u64 << 62;
            let a = m["cells"][0]["count"].as_u64().unwrap();
            let n = m["point_count"].as_u64().unwrap() - a + huge;
            m["cells"][0]["count"] = huge.into();
            m["point_count"] = n.into();
            m["inputs"][0]["points"] = (n + m["skipped_invalid"].as_u64().unwrap()).into();
        }),
    );
    c.store(
        base,
        "store_bad_compression",
        Info,
        NONE,
        &edit(|m| m["compression"] = "lz4".into()),
    );
    c.store(
        base,
        "store_bad_record_fields",
        Info,
        NONE,
        &edit(|m| {
            m["record_fields"][0] = "x:f16".into();
        }),
    );
    c.store(
        base,
        "store_unsorted_cells",
        Info,
        CELL,
        &edit(|m| {
            m["cells"].as_array_mut().unwrap().swap(0, 1);
        }),
    );
}

/// Damaged cell files and store directories.
pub(super) fn store_file_cases(c: &mut Corpus, base: &Path) {
    use Cmd::*;
    #[cfg(unix)]
    c.store(base, "store_symlink_out", Info, CELL, &|st: &Path| {
        let cell = cell_file(st, 1);
        let outside = st.parent().unwrap().join("outside.zst");
        std::fs::rename(&cell, &outside).unwrap();
        std::os::unix::fs::symlink(&outside, &cell).unwrap();
        st.to_path_buf()
    });
    c.store(base, "store_missing_cell", Info, CELL, &|st: &Path| {
        std::fs::remove_file(cell_file(st, 2)).unwrap();
        st.to_path_buf()
    });
    c.store(base, "store_truncated_cell", Info, CELL, &|st: &Path| {
        let cell = cell_file(st, 2);
        let b = std::fs::read(&cell).unwrap();
        std::fs::write(&cell, &b[..b.len() / 3]).unwrap();
        st.to_path_buf()
    });
    let corrupt = |st: &Path| {
        let cell = cell_file(st, 1);
        let mut b = std::fs::read(&cell).unwrap();
        let mid = b.len() / 2;
        b[mid] ^= 0x33;
        std::fs::write(&cell, &b).unwrap();
        cell
    };
    c.store(base, "store_corrupt_cell_verify", Verify, NONE, &corrupt);
    c.store(
        base,
        "store_corrupt_cell_reconstruct",
        Reconstruct,
        NONE,
        &corrupt,
    );
    let junk_cell = |st: &Path| {
        let cell = cell_file(st, 0);
        let n = std::fs::metadata(&cell).unwrap().len() as usize;
        std::fs::write(&cell, junk(n, 3)).unwrap();
        cell
    };
    c.store(base, "store_junk_cell_verify", Verify, NONE, &junk_cell);
    let manifest_bytes = |bytes: Vec<u8>| {
        move |st: &Path| {
            std::fs::write(st.join("manifest.json"), &bytes).unwrap();
            st.join("manifest.json")
        }
    };
    c.store(
        base,
        "store_garbage_manifest",
        Info,
        NONE,
        &manifest_bytes(junk(2000, 9)),
    );
    c.store(
        base,
        "store_empty_json_manifest",
        Info,
        NONE,
        &manifest_bytes(b"{}".to_vec()),
    );
    let half = std::fs::read(base.join("manifest.json")).unwrap();
    let half = half[..half.len() / 2].to_vec();
    c.store(
        base,
        "store_truncated_manifest",
        Info,
        LINE,
        &manifest_bytes(half.clone()),
    );
    c.store(
        base,
        "store_truncated_manifest_reconstruct",
        Reconstruct,
        LINE,
        &manifest_bytes(half),
    );
    c.store(
        base,
        "store_wrong_version",
        Info,
        NONE,
        &edit(|m| m["version"] = 99.into()),
    );
    c.store(base, "store_missing_manifest", Info, NONE, &|st: &Path| {
        std::fs::remove_file(st.join("manifest.json")).unwrap();
        st.to_path_buf()
    });
    #[cfg(unix)]
    c.store(base, "store_fifo_manifest", Info, NONE, &|st: &Path| {
        let m = st.join("manifest.json");
        std::fs::remove_file(&m).unwrap();
        // A FIFO (reading it would block), or a directory where mkfifo is missing.
        let made = Command::new("mkfifo").arg(&m).status();
        if !matches!(made, Ok(s) if s.success()) {
            std::fs::create_dir(&m).unwrap();
        }
        m
    });
    c.store(base, "store_missing_cells_dir", Info, NONE, &|st: &Path| {
        std::fs::remove_dir_all(st.join("cells")).unwrap();
        st.to_path_buf()
    });
}
