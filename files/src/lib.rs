//! Files written whole or not at all, and never over an existing file unless the caller says
//! so.
//!
//! Every file the project writes (bitstreams, clips, `stimuli.json`, `rd.csv`, reports,
//! tables, figures, databases, marker files, images) goes through this crate, so that a crash
//! or a full disk never leaves a truncated file under a final name, and a second run never
//! silently replaces the first one's outputs:
//!
//! 1. the bytes go to a temporary file beside the target (`.<name>.<pid>-<n>.tmp`, created
//!    with `O_EXCL`, so two writers never share one);
//! 2. the temporary file is fsynced;
//! 3. it takes the final name: [`Mode::Replace`] renames it (over an existing file, which a
//!    reader then sees whole, old or new), [`Mode::New`] hard-links it, which the kernel
//!    refuses when the name exists, and removes the temporary name;
//! 4. the folder is fsynced, so the new name survives a power cut (Linux).
//!
//! On every error before the final name is taken the temporary file is removed; what is
//! left under the final name is the old file or nothing. Only a process killed outright
//! (SIGKILL, power cut) can leave a temporary file behind, and never under a final name.
//!
//! [`write()`] takes bytes in memory; [`AtomicFile`] gives a [`std::io::Write`] for encoders
//! that stream (PNG, CSV) and commits on [`AtomicFile::commit`]; [`TempPath`] is a reserved
//! name for libraries that write only by path.
//!
//! ```
//! use std::io::Write as _;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let dir = std::env::temp_dir().join(format!("files-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let path = dir.join("rd.csv");
//! # let _ = std::fs::remove_file(&path);
//! files::write(&path, b"clip,codec\n", files::Mode::New)?;
//! // A second write of a new file under the same name is refused ...
//! assert!(files::write(&path, b"other\n", files::Mode::New).unwrap_err().is_refusal());
//! // ... and replacing it must be asked for.
//! let mut out = files::AtomicFile::create(&path, files::Mode::Replace)?;
//! writeln!(out, "clip,codec")?;
//! writeln!(out, "walk,spiht")?;
//! out.commit()?;
//! assert_eq!(std::fs::read_to_string(&path)?, "clip,codec\nwalk,spiht\n");
//! # std::fs::remove_dir_all(&dir)?;
//! # Ok(())
//! # }
//! ```

use std::fmt;
use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// What to do when the target already exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mode {
    /// Refuse an existing target ([`Error::Exists`]); the default.
    #[default]
    New,
    /// Replace an existing target atomically (a reader sees the old file or the new one).
    Replace,
}

impl Mode {
    /// [`Mode::Replace`] when `force` (a `--force` flag), else [`Mode::New`].
    pub fn from_force(force: bool) -> Self {
        if force { Self::Replace } else { Self::New }
    }
}

/// Why a file was not written. Every variant names the path.
#[derive(Debug)]
#[non_exhaustive]
pub enum Error {
    /// The target exists and [`Mode::New`] was asked for.
    Exists {
        /// The existing target.
        path: PathBuf,
    },
    /// An output folder holds entries and [`Mode::New`] was asked for ([`prepare_dir`]).
    NotEmpty {
        /// The folder.
        dir: PathBuf,
        /// The first few entries, sorted by name (folders end in `/`).
        found: Vec<String>,
        /// How many entries it holds in all.
        entries: usize,
    },
    /// An I/O call failed.
    Io {
        /// The file or folder it was on.
        path: PathBuf,
        /// What was being done (`create`, `write`, `fsync`, `rename`, `link`, ...).
        op: &'static str,
        /// The OS error.
        source: io::Error,
    },
}

impl Error {
    /// The file or folder the error is about.
    pub fn path(&self) -> &Path {
        match self {
            Self::Exists { path } | Self::Io { path, .. } => path,
            Self::NotEmpty { dir, .. } => dir,
        }
    }

    /// Whether this is a refusal to replace or write into existing outputs (not an I/O
    /// failure): [`Error::Exists`] or [`Error::NotEmpty`].
    pub fn is_refusal(&self) -> bool {
        matches!(self, Self::Exists { .. } | Self::NotEmpty { .. })
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Exists { path } => write!(
                f,
                "{} already exists; nothing was replaced (--force replaces it)",
                path.display()
            ),
            Self::NotEmpty {
                dir,
                found,
                entries,
            } => {
                write!(
                    f,
                    "{} is not empty: it holds {}",
                    dir.display(),
                    found.join(", ")
                )?;
                if *entries > found.len() {
                    write!(f, " and {} more", entries - found.len())?;
                }
                write!(
                    f,
                    "; nothing was written (--force writes into it, replacing files of the same names)"
                )
            }
            Self::Io { path, op, source } => write!(f, "{}: {op}: {source}", path.display()),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        // The OS error is part of the message already; a chain printer would say it twice.
        None
    }
}

fn io_err(path: &Path, op: &'static str) -> impl FnOnce(io::Error) -> Error {
    let path = path.to_path_buf();
    move |source| Error::Io { path, op, source }
}

/// The folder a target lives in (`.` for a bare file name).
fn parent_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Temporary names handed out by this process so far (with the pid, unique on the machine).
static NEXT: AtomicU64 = AtomicU64::new(0);

/// Longest part of the target's name kept in a temporary name, bytes: with the pid, counter
/// and extension the name stays under the 255-byte limit of common file systems.
const MAX_STEM_BYTES: usize = 200;

/// A reserved temporary file beside a target, removed on drop unless it was renamed.
///
/// Its name is `.<target name>.<pid>-<n>.<extension>`, created empty with `O_EXCL`, so no
/// other writer (thread or process) holds the same name. It is for libraries that write only
/// to a path they open themselves (the C3D writer); [`AtomicFile`] and [`write()`] use it for
/// their own temporary file.
#[derive(Debug)]
pub struct TempPath {
    path: PathBuf,
    armed: bool,
}

impl TempPath {
    /// Reserves a temporary file beside `target` ending in `.extension` (no dot).
    ///
    /// # Errors
    /// [`Error::Io`] when `target` has no file name or the folder refuses a new file.
    pub fn beside(target: &Path, extension: &str) -> Result<Self, Error> {
        Self::create(target, extension).map(|(t, _)| t)
    }

    /// Reserves a temporary file and returns it opened for writing.
    fn create(target: &Path, extension: &str) -> Result<(Self, File), Error> {
        let Some(name) = target.file_name() else {
            return Err(Error::Io {
                path: target.to_path_buf(),
                op: "create",
                source: io::Error::new(io::ErrorKind::InvalidInput, "not a file name"),
            });
        };
        let name = name.to_string_lossy();
        let mut cut = name.len().min(MAX_STEM_BYTES);
        while !name.is_char_boundary(cut) {
            cut -= 1;
        }
        let dir = parent_of(target);
        let pid = std::process::id();
        let mut last = None;
        // A name already taken is one left by a killed process with our pid (pids are
        // reused): take the next.
        for _ in 0..64 {
            let n = NEXT.fetch_add(1, Ordering::Relaxed);
            let path = dir.join(format!(".{}.{pid}-{n}.{extension}", &name[..cut]));
            match OpenOptions::new().write(true).create_new(true).open(&path) {
                Ok(file) => return Ok((Self { path, armed: true }, file)),
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => last = Some(e),
                Err(e) => return Err(io_err(target, "create a temporary file")(e)),
            }
        }
        let e = last.unwrap_or_else(|| io::Error::from(io::ErrorKind::AlreadyExists));
        Err(io_err(target, "create a temporary file")(e))
    }

    /// The temporary file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Stops the drop from removing the file (it was renamed away).
    fn disarm(&mut self) {
        self.armed = false;
    }
}

impl Drop for TempPath {
    fn drop(&mut self) {
        if self.armed {
            let _ = fs::remove_file(&self.path);
        }
    }
}

/// A file being written under a temporary name, given its final name by [`commit`]
/// (fsync, rename or no-clobber link, fsync of the folder); dropped without a commit, the
/// temporary file is removed and the target is untouched.
///
/// Writes are buffered. Write errors (a full disk) come back from the `Write` calls or from
/// [`commit`]; either way nothing appears under the final name.
///
/// [`commit`]: AtomicFile::commit
#[derive(Debug)]
pub struct AtomicFile {
    // Declared before `temp`: the descriptor is closed before the temporary name is removed.
    file: Option<BufWriter<File>>,
    temp: TempPath,
    target: PathBuf,
    mode: Mode,
}

impl AtomicFile {
    /// Starts writing `path`. With [`Mode::New`] an existing `path` is refused here already
    /// (and again, race-free, at [`commit`](AtomicFile::commit)).
    ///
    /// # Errors
    /// [`Error::Exists`], or [`Error::Io`] when the temporary file cannot be created.
    pub fn create(path: &Path, mode: Mode) -> Result<Self, Error> {
        check_new(path, mode)?;
        let (temp, file) = TempPath::create(path, "tmp")?;
        Ok(Self {
            file: Some(BufWriter::new(file)),
            temp,
            target: path.to_path_buf(),
            mode,
        })
    }

    /// The final name.
    pub fn path(&self) -> &Path {
        &self.target
    }

    /// Flushes and fsyncs the temporary file, gives it its final name and fsyncs the folder.
    ///
    /// # Errors
    /// [`Error::Exists`] when [`Mode::New`] and the target appeared meanwhile; [`Error::Io`]
    /// naming the step that failed. The temporary file is removed in both cases (after a
    /// failed folder fsync the file is complete under its final name).
    pub fn commit(mut self) -> Result<(), Error> {
        let Some(buffered) = self.file.take() else {
            return Err(io_err(&self.target, "write")(io::Error::other(
                "the file was already closed",
            )));
        };
        // Errors name the target: the temporary name means nothing to whoever reads them.
        let file = buffered
            .into_inner()
            .map_err(|e| io_err(&self.target, "write")(e.into_error()))?;
        file.sync_all().map_err(io_err(&self.target, "fsync"))?;
        drop(file);
        let tmp = self.temp.path().to_path_buf();
        match self.mode {
            Mode::Replace => {
                fs::rename(&tmp, &self.target).map_err(io_err(&self.target, "rename"))?;
                self.temp.disarm();
            }
            Mode::New => match fs::hard_link(&tmp, &self.target) {
                // The temporary name goes with `self.temp`.
                Ok(()) => {}
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {
                    return Err(Error::Exists {
                        path: self.target.clone(),
                    });
                }
                Err(e) => return Err(io_err(&self.target, "link")(e)),
            },
        }
        sync_dir(parent_of(&self.target))
    }

    fn buffer(&mut self) -> io::Result<&mut BufWriter<File>> {
        self.file
            .as_mut()
            .ok_or_else(|| io::Error::other("the file was already closed"))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.buffer()?.write(buf)
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.buffer()?.write_all(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.buffer()?.flush()
    }
}

/// Writes `bytes` to `path` whole or not at all (see the crate docs).
///
/// # Errors
/// [`Error::Exists`] when [`Mode::New`] and `path` exists; [`Error::Io`] naming the file and
/// the step. Nothing is left under the final name or the temporary one.
pub fn write(path: &Path, bytes: impl AsRef<[u8]>, mode: Mode) -> Result<(), Error> {
    write_through(AtomicFile::create(path, mode)?, bytes.as_ref())
}

fn write_through(mut file: AtomicFile, bytes: &[u8]) -> Result<(), Error> {
    let target = file.target.clone();
    file.write_all(bytes).map_err(io_err(&target, "write"))?;
    file.commit()
}

/// With [`Mode::New`], refuses `path` if it exists (as a file, folder or link); with
/// [`Mode::Replace`], accepts anything. For commands that write several files, to refuse
/// before writing the first of them.
///
/// # Errors
/// [`Error::Exists`].
pub fn check_new(path: &Path, mode: Mode) -> Result<(), Error> {
    if mode == Mode::New && fs::symlink_metadata(path).is_ok() {
        return Err(Error::Exists {
            path: path.to_path_buf(),
        });
    }
    Ok(())
}

/// Entries of a non-empty folder listed by [`Error::NotEmpty`].
const LISTED_ENTRIES: usize = 5;

/// Makes `dir` (and its parents) an output folder: created if missing; with [`Mode::New`] an
/// existing folder must be empty.
///
/// # Errors
/// [`Error::NotEmpty`] naming what the folder holds; [`Error::Io`] when it cannot be created
/// or read (or is a file).
pub fn prepare_dir(dir: &Path, mode: Mode) -> Result<(), Error> {
    fs::create_dir_all(dir).map_err(io_err(dir, "create folder"))?;
    if mode == Mode::Replace {
        return Ok(());
    }
    let mut names = Vec::new();
    for entry in fs::read_dir(dir).map_err(io_err(dir, "read folder"))? {
        let entry = entry.map_err(io_err(dir, "read folder"))?;
        let mut name = entry.file_name().to_string_lossy().into_owned();
        if entry.file_type().is_ok_and(|t| t.is_dir()) {
            name.push('/');
        }
        names.push(name);
    }
    if names.is_empty() {
        return Ok(());
    }
    names.sort();
    let entries = names.len();
    names.truncate(LISTED_ENTRIES);
    Err(Error::NotEmpty {
        dir: dir.to_path_buf(),
        found: names,
        entries,
    })
}

/// fsync of a folder, so a rename or a new entry in it survives a power cut (Linux; a no-op
/// where folders cannot be opened).
///
/// # Errors
/// [`Error::Io`].
pub fn sync_dir(dir: &Path) -> Result<(), Error> {
    #[cfg(unix)]
    {
        File::open(dir)
            .and_then(|d| d.sync_all())
            .map_err(io_err(dir, "fsync folder"))
    }
    #[cfg(not(unix))]
    {
        let _ = dir;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

    use super::*;

    /// A fresh, empty folder for one test.
    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("files-test-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    /// Every entry of `dir`, sorted.
    fn entries(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    /// An [`AtomicFile`] for `path` whose writes go to `/dev/full` (every write fails with
    /// ENOSPC, as on a full disk), while its temporary file exists on disk as a real one
    /// would.
    fn on_a_full_disk(path: &Path, mode: Mode) -> AtomicFile {
        let mut f = AtomicFile::create(path, mode).unwrap();
        assert_eq!(
            entries(parent_of(path)).len(),
            1 + usize::from(path.exists())
        );
        let full = OpenOptions::new().write(true).open("/dev/full").unwrap();
        f.file = Some(BufWriter::new(full));
        f
    }

    fn is_enospc(e: &Error) -> bool {
        matches!(e, Error::Io { source, .. } if source.raw_os_error() == Some(28))
    }

    #[test]
    fn writes_a_new_file_and_leaves_only_it() {
        let dir = scratch("new");
        let p = dir.join("rd.csv");
        write(&p, "a,b\n", Mode::New).unwrap();
        assert_eq!(fs::read_to_string(&p).unwrap(), "a,b\n");
        assert_eq!(entries(&dir), ["rd.csv"]);
    }

    #[test]
    fn new_refuses_an_existing_file_and_keeps_it() {
        let dir = scratch("refuse");
        let p = dir.join("stimuli.json");
        fs::write(&p, "old").unwrap();
        let e = write(&p, "new", Mode::New).unwrap_err();
        assert!(matches!(&e, Error::Exists { path } if path == &p), "{e}");
        assert!(e.to_string().contains("stimuli.json already exists"), "{e}");
        assert_eq!(fs::read_to_string(&p).unwrap(), "old");
        assert_eq!(entries(&dir), ["stimuli.json"]);
        // A folder of that name is refused as well.
        let sub = dir.join("sub");
        fs::create_dir(&sub).unwrap();
        assert!(matches!(
            write(&sub, "x", Mode::New),
            Err(Error::Exists { .. })
        ));
        assert_eq!(entries(&dir), ["stimuli.json", "sub"]);
    }

    #[test]
    fn replace_replaces_whole() {
        let dir = scratch("replace");
        let p = dir.join("report.md");
        fs::write(&p, "old").unwrap();
        write(&p, "new", Mode::Replace).unwrap();
        assert_eq!(fs::read_to_string(&p).unwrap(), "new");
        assert_eq!(entries(&dir), ["report.md"]);
    }

    #[test]
    fn a_target_that_appears_during_the_write_is_not_replaced() {
        let dir = scratch("race");
        let p = dir.join("x.mcz");
        let mut f = AtomicFile::create(&p, Mode::New).unwrap();
        f.write_all(b"mine").unwrap();
        fs::write(&p, "theirs").unwrap();
        assert!(matches!(f.commit(), Err(Error::Exists { .. })));
        assert_eq!(fs::read_to_string(&p).unwrap(), "theirs");
        assert_eq!(entries(&dir), ["x.mcz"]);
    }

    #[test]
    fn of_many_writers_of_one_new_file_exactly_one_succeeds() {
        let dir = scratch("threads");
        let p = dir.join("db.mpdb");
        let wins: usize = std::thread::scope(|s| {
            let handles: Vec<_> = (0..8)
                .map(|i| {
                    let p = &p;
                    s.spawn(move || usize::from(write(p, format!("{i}"), Mode::New).is_ok()))
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).sum()
        });
        assert_eq!(wins, 1);
        assert_eq!(entries(&dir), ["db.mpdb"]);
    }

    #[test]
    fn a_full_disk_leaves_nothing_under_the_final_name_nor_a_temporary() {
        let dir = scratch("full");
        let p = dir.join("walk-cr10.mcz");
        // More than the buffer: the failure comes from `write`.
        let e = write_through(on_a_full_disk(&p, Mode::New), &vec![7u8; 1 << 20]).unwrap_err();
        assert!(is_enospc(&e), "{e}");
        assert_eq!(e.path(), p);
        assert_eq!(entries(&dir), Vec::<String>::new());
        // Less than the buffer: the failure comes from the flush in `commit`.
        let e = write_through(on_a_full_disk(&p, Mode::New), b"short").unwrap_err();
        assert!(is_enospc(&e), "{e}");
        assert_eq!(entries(&dir), Vec::<String>::new());
        // Streamed, then dropped after the error.
        let mut f = on_a_full_disk(&p, Mode::New);
        assert!(f.write_all(&vec![1u8; 1 << 20]).is_err());
        drop(f);
        assert_eq!(entries(&dir), Vec::<String>::new());
    }

    #[test]
    fn a_full_disk_during_a_replace_keeps_the_old_file_whole() {
        let dir = scratch("full-replace");
        let p = dir.join("stimuli.json");
        fs::write(&p, "the old manifest").unwrap();
        let e = write_through(on_a_full_disk(&p, Mode::Replace), b"new").unwrap_err();
        assert!(is_enospc(&e), "{e}");
        assert_eq!(fs::read_to_string(&p).unwrap(), "the old manifest");
        assert_eq!(entries(&dir), ["stimuli.json"]);
    }

    #[test]
    fn a_failed_rename_removes_the_temporary_file() {
        let dir = scratch("rename");
        // A non-empty folder under the target name: rename(2) refuses to replace it.
        let p = dir.join("figures");
        fs::create_dir(&p).unwrap();
        fs::write(p.join("a.svg"), "svg").unwrap();
        let e = write(&p, "x", Mode::Replace).unwrap_err();
        assert!(matches!(&e, Error::Io { op: "rename", .. }), "{e}");
        assert_eq!(entries(&dir), ["figures"]);
        assert_eq!(entries(&p), ["a.svg"]);
    }

    #[test]
    fn a_missing_folder_is_an_error_naming_it() {
        let dir = scratch("missing");
        let p = dir.join("no/such/folder/x.csv");
        let e = write(&p, "x", Mode::Replace).unwrap_err();
        assert!(
            matches!(
                &e,
                Error::Io {
                    op: "create a temporary file",
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("no/such/folder"), "{e}");
    }

    #[test]
    fn dropping_an_uncommitted_file_removes_it() {
        let dir = scratch("drop");
        let p = dir.join("x.png");
        let mut f = AtomicFile::create(&p, Mode::New).unwrap();
        f.write_all(b"half a png").unwrap();
        f.flush().unwrap();
        assert_eq!(entries(&dir).len(), 1);
        drop(f);
        assert_eq!(entries(&dir), Vec::<String>::new());
    }

    #[test]
    fn temporary_names_are_unique_hidden_and_beside_the_target() {
        let dir = scratch("names");
        let p = dir.join("walk.c3d");
        let a = TempPath::beside(&p, "c3d").unwrap();
        let b = TempPath::beside(&p, "c3d").unwrap();
        assert_ne!(a.path(), b.path());
        for t in [&a, &b] {
            assert_eq!(t.path().parent(), Some(dir.as_path()));
            let name = t.path().file_name().unwrap().to_string_lossy().into_owned();
            assert!(name.starts_with(".walk.c3d."), "{name}");
            assert_eq!(t.path().extension(), Some("c3d".as_ref()), "{name}");
        }
        drop((a, b));
        assert_eq!(entries(&dir), Vec::<String>::new());
        // A very long name still makes a temporary name the file system takes.
        let long = dir.join(format!("{}.csv", "é".repeat(120)));
        write(&long, "x", Mode::New).unwrap();
        assert_eq!(entries(&dir).len(), 1);
    }

    #[test]
    fn a_bare_file_name_is_written_in_the_current_folder() {
        assert_eq!(parent_of(Path::new("x.csv")), Path::new("."));
        assert_eq!(parent_of(Path::new("a/x.csv")), Path::new("a"));
    }

    #[test]
    fn an_output_folder_must_be_empty_unless_replacing() {
        let dir = scratch("prepare");
        let out = dir.join("stimuli");
        prepare_dir(&out, Mode::New).unwrap();
        assert!(out.is_dir());
        prepare_dir(&out, Mode::New).unwrap();
        for name in ["b.csv", "a.json", "c", "d", "e", "f"] {
            fs::write(out.join(name), "").unwrap();
        }
        fs::create_dir(out.join("walk")).unwrap();
        let e = prepare_dir(&out, Mode::New).unwrap_err();
        let Error::NotEmpty {
            found, entries: n, ..
        } = &e
        else {
            panic!("{e}");
        };
        assert_eq!(found, &["a.json", "b.csv", "c", "d", "e"]);
        assert_eq!(*n, 7);
        let text = e.to_string();
        assert!(
            text.contains("stimuli is not empty: it holds a.json, b.csv, c, d, e and 2 more"),
            "{text}"
        );
        assert!(e.is_refusal());
        prepare_dir(&out, Mode::Replace).unwrap();
        // A file where the folder should be.
        let e = prepare_dir(&out.join("b.csv"), Mode::Replace).unwrap_err();
        assert!(matches!(e, Error::Io { .. }), "{e}");
    }

    #[test]
    fn check_new_sees_files_folders_and_dangling_links() {
        let dir = scratch("check");
        let p = dir.join("x");
        check_new(&p, Mode::New).unwrap();
        #[cfg(unix)]
        std::os::unix::fs::symlink(dir.join("nowhere"), &p).unwrap();
        #[cfg(not(unix))]
        fs::write(&p, "").unwrap();
        assert!(matches!(
            check_new(&p, Mode::New),
            Err(Error::Exists { .. })
        ));
        check_new(&p, Mode::Replace).unwrap();
        assert_eq!(Mode::from_force(true), Mode::Replace);
        assert_eq!(Mode::from_force(false), Mode::New);
    }
}
