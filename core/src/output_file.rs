//! Writing outputs: the one writer of every file tress produces (renders, previews, merged
//! images, CSVs, reports, plots, fitted settings, study caches).
//!
//! What a path names decides how it is written:
//!
//! - **nothing yet, or a regular file**: the bytes go to a temporary file in the target's folder,
//!   which is synced, renamed over the target, and the folder synced, so a reader sees the old
//!   file or the new one and never half of one, and a failure leaves no output behind. A symbolic
//!   link to a regular file (or to nothing yet) is followed: the file it points to is replaced
//!   beside itself, and the link survives.
//! - **a character device or a FIFO** (directly or through links: `/dev/null`, `/dev/stdout`
//!   at a terminal or into a pipe): the finished bytes are written into it; it is never
//!   replaced by a file. A FIFO that no process is reading is refused at once rather than
//!   waited on.
//! - **a file some process has open, named through /proc** (`/dev/stdout` redirected to a file,
//!   `/dev/fd/N`): written through this process's own descriptor, where its other writes go, or
//!   appended to another process's file; renaming a new file over its name would leave the
//!   process writing into a deleted one.
//! - **a directory, a block device or a socket**: refused by name.
//!
//! An output may not replace a file its own command reads ([`Inputs`]): a path that is an input,
//! under any name (`..` segments, symbolic links) or as a hard link of one, is refused by name.

// The one writer: the rules of clippy.toml that keep every other file of library code from
// creating or replacing files do not apply here.
#![allow(clippy::disallowed_methods, clippy::disallowed_types)]

use std::fs::{File, Metadata};
use std::io::{BufWriter, Cursor, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Why an output could not be written; every error names the path given.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// Creating, writing, syncing or renaming failed. The message leaves the cause to the
    /// source, so that a chain printed whole (`{:#}`) names it once.
    #[error("{}: cannot {action}", path.display())]
    Io {
        /// The output.
        path: PathBuf,
        /// What was attempted, e.g. `sync`.
        action: &'static str,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The path is a directory.
    #[error("{}: is a directory, not a file to write", path.display())]
    Directory {
        /// The output.
        path: PathBuf,
    },
    /// The path is a kind of file tress neither replaces nor writes into.
    #[error(
        "{}: is a {kind}: outputs are written to regular files, character devices and FIFOs \
         only, so it was left alone",
        path.display()
    )]
    Unwritable {
        /// The output.
        path: PathBuf,
        /// `block device` or `socket`.
        kind: &'static str,
    },
    /// The path is a FIFO no process has open for reading.
    #[error(
        "{}: is a FIFO that no process is reading: nothing was written (start its reader first)",
        path.display()
    )]
    NoReader {
        /// The output.
        path: PathBuf,
    },
    /// The path is a file the command reads.
    #[error(
        "{}: is {}, an input of this command: refusing to overwrite it",
        path.display(),
        input.display()
    )]
    Input {
        /// The output.
        path: PathBuf,
        /// The input it would replace, as the command was given it.
        input: PathBuf,
    },
    /// What the path names changed between the output's start and its rename.
    #[error("{}: changed while the output was being written: nothing was written", path.display())]
    Changed {
        /// The output.
        path: PathBuf,
    },
}

fn io_error(path: &Path, action: &'static str) -> impl FnOnce(std::io::Error) -> OutputError {
    let path = path.to_owned();
    move |source| OutputError::Io {
        path,
        action,
        source,
    }
}

/// The files a command reads, which none of its outputs may replace. Each is recorded by its
/// canonical path and its identity (device and inode), so a hard link or another spelling of
/// the path is recognised as well.
#[derive(Clone, Debug, Default)]
pub struct Inputs {
    files: Vec<Input>,
}

#[derive(Clone, Debug)]
struct Input {
    path: PathBuf,
    canonical: Option<PathBuf>,
    identity: Option<Identity>,
}

/// Device and inode: the same file under any name.
type Identity = (u64, u64);

#[cfg(unix)]
fn identity(meta: &Metadata) -> Option<Identity> {
    use std::os::unix::fs::MetadataExt;
    Some((meta.dev(), meta.ino()))
}

#[cfg(not(unix))]
fn identity(_: &Metadata) -> Option<Identity> {
    None
}

impl Inputs {
    /// Records `path` as an input. A path that does not exist yet is kept by name (its reader
    /// reports it missing).
    pub fn add(&mut self, path: impl AsRef<Path>) {
        let path = path.as_ref();
        self.files.push(Input {
            path: path.to_owned(),
            canonical: std::fs::canonicalize(path).ok(),
            identity: std::fs::metadata(path).ok().as_ref().and_then(identity),
        });
    }

    /// The input that `canonical` or `id` names, if any.
    fn find(&self, canonical: Option<&Path>, id: Option<Identity>) -> Option<&Path> {
        self.files
            .iter()
            .find(|f| {
                (id.is_some() && f.identity == id)
                    || (canonical.is_some() && f.canonical.as_deref() == canonical)
            })
            .map(|f| f.path.as_path())
    }
}

impl<P: AsRef<Path>> Extend<P> for Inputs {
    fn extend<I: IntoIterator<Item = P>>(&mut self, paths: I) {
        paths.into_iter().for_each(|p| self.add(p));
    }
}

impl<P: AsRef<Path>> FromIterator<P> for Inputs {
    fn from_iter<I: IntoIterator<Item = P>>(paths: I) -> Self {
        let mut inputs = Inputs::default();
        inputs.extend(paths);
        inputs
    }
}

/// How an output reaches its path.
#[derive(Debug, PartialEq)]
enum Target {
    /// Renamed over `file`: the path with its symbolic links followed (a regular file, or
    /// nothing yet).
    Replace { file: PathBuf },
    /// Written into, at its end: a character device, a FIFO, or a file open in a process.
    Stream(Stream),
}

/// How a [`Target::Stream`] is opened.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stream {
    /// By its path.
    Path,
    /// Through a copy of this process's own descriptor `fd` (`/dev/stdout`, `/dev/fd/N`,
    /// `/proc/self/fd/N`), so that the output lands where the process's own writes to it do:
    /// opening the path again would start at another offset and overwrite them.
    Descriptor(i32),
}

/// Where the symbolic links of an output's path lead.
enum Followed {
    /// A file, or the name of one yet to be made.
    File(PathBuf),
    /// A link in /proc (`/dev/stdout`, `/proc/self/fd/1`): the kernel's handle on a file some
    /// process has open (this one's descriptor, if it is), which renaming a new file over its
    /// name would take away from that process.
    OpenFile(Option<i32>),
}

/// Symbolic links followed from `path` to what they finally name (which may not exist yet);
/// relative links resolve against their own folder.
fn follow_links(path: &Path) -> std::io::Result<Followed> {
    // As many as Linux follows before giving up with ELOOP.
    const MAX_LINKS: usize = 40;
    let own_descriptors = Path::new("/proc")
        .join(std::process::id().to_string())
        .join("fd");
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let dir = std::fs::canonicalize(folder(&p))?;
                if dir.starts_with("/proc") {
                    let fd = p.file_name().and_then(|n| n.to_str()?.parse().ok());
                    return Ok(Followed::OpenFile(fd.filter(|_| dir == own_descriptors)));
                }
                let to = std::fs::read_link(&p)?;
                p = folder(&p).join(to);
            }
            Ok(_) => return Ok(Followed::File(p)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Followed::File(p)),
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::other(format!(
        "more than {MAX_LINKS} symbolic links in a row"
    )))
}

/// `file`'s folder, canonical, joined with its name: how an input would be recorded.
fn canonical_file(file: &Path) -> Option<PathBuf> {
    let dir = folder(file);
    Some(std::fs::canonicalize(dir).ok()?.join(file.file_name()?))
}

/// The folder a file is in (`.` for a bare name).
fn folder(file: &Path) -> &Path {
    match file.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// What `path` names and how an output is written there; refuses what may not be written.
fn target(path: &Path, inputs: &Inputs) -> Result<Target, OutputError> {
    // The kernel's own resolution: `/dev/stdout` may lead through /proc to a pipe that no path
    // names.
    let meta = match std::fs::metadata(path) {
        Ok(m) => Some(m),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(io_error(path, "inspect it")(e)),
    };
    if meta.as_ref().is_some_and(|m| m.is_dir()) {
        return Err(OutputError::Directory {
            path: path.to_owned(),
        });
    }
    let followed = follow_links(path).map_err(io_error(path, "follow its symbolic links"))?;
    let (target, canonical) = match (followed, &meta) {
        (Followed::OpenFile(Some(fd)), Some(m)) => {
            (special(path, m, Stream::Descriptor(fd))?, None)
        }
        (_, Some(m)) if !m.is_file() => (special(path, m, Stream::Path)?, None),
        (Followed::OpenFile(_), _) => (Target::Stream(Stream::Path), None),
        (Followed::File(file), _) => {
            if file.file_name().is_none() {
                return Err(OutputError::Directory {
                    path: path.to_owned(),
                });
            }
            let canonical = canonical_file(&file);
            (Target::Replace { file }, canonical)
        }
    };
    if let Some(input) = inputs.find(canonical.as_deref(), meta.as_ref().and_then(identity)) {
        return Err(OutputError::Input {
            path: path.to_owned(),
            input: input.to_owned(),
        });
    }
    Ok(target)
}

/// A path written into as `stream`, if its kind allows: character devices and FIFOs, and
/// anything but a block device through this process's own descriptor (a redirected stdout may
/// be a file or a socket); the rest is refused.
#[cfg(unix)]
fn special(path: &Path, meta: &Metadata, stream: Stream) -> Result<Target, OutputError> {
    use std::os::unix::fs::FileTypeExt;
    let kind = meta.file_type();
    let own = matches!(stream, Stream::Descriptor(_));
    if kind.is_char_device() || kind.is_fifo() || (own && !kind.is_block_device()) {
        return Ok(Target::Stream(stream));
    }
    Err(OutputError::Unwritable {
        path: path.to_owned(),
        kind: if kind.is_block_device() {
            "block device"
        } else if kind.is_socket() {
            "socket"
        } else {
            "special file"
        },
    })
}

#[cfg(not(unix))]
fn special(path: &Path, _: &Metadata, _: Stream) -> Result<Target, OutputError> {
    Err(OutputError::Unwritable {
        path: path.to_owned(),
        kind: "special file",
    })
}

/// Refuses, before any work, an output that could not be written to `path`: a directory, a
/// block device or socket, or one of `inputs`. Writing checks all of this again.
pub fn check(path: &Path, inputs: &Inputs) -> Result<(), OutputError> {
    target(path, inputs).map(|_| ())
}

/// Where an output's bytes go while it is written: a temporary file beside the target, or
/// memory for a device or FIFO (written into it only once complete, and seekable, as EXR
/// writing needs).
pub struct Sink {
    path: PathBuf,
    to: SinkTo,
}

enum SinkTo {
    /// A temporary file, to be renamed over `file`.
    File {
        file: PathBuf,
        tmp: BufWriter<tempfile::NamedTempFile>,
    },
    /// Memory, to be written into a stream once complete.
    Memory {
        stream: Stream,
        bytes: Cursor<Vec<u8>>,
    },
}

impl Sink {
    /// The output's path as given, for messages.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        match &mut self.to {
            SinkTo::File { tmp: w, .. } => w.write(buf),
            SinkTo::Memory { bytes: w, .. } => w.write(buf),
        }
    }

    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.to {
            SinkTo::File { tmp: w, .. } => w.flush(),
            SinkTo::Memory { bytes: w, .. } => w.flush(),
        }
    }
}

impl Seek for Sink {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        match &mut self.to {
            SinkTo::File { tmp: w, .. } => w.seek(pos),
            SinkTo::Memory { bytes: w, .. } => w.seek(pos),
        }
    }
}

/// A temporary file in `dir` for an output to be renamed into place. Created with the mode of
/// an ordinary new file (0666 less the umask) instead of tempfile's private 0600, so the renamed
/// output is readable like any other.
fn temp_file(dir: &Path) -> std::io::Result<tempfile::NamedTempFile> {
    let mut builder = tempfile::Builder::new();
    builder.prefix(".tress-").suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    builder.tempfile_in(dir)
}

/// An output written completely, waiting to be put in place.
enum Staged {
    Replace {
        path: PathBuf,
        file: PathBuf,
        tmp: tempfile::NamedTempFile,
    },
    Stream {
        path: PathBuf,
        stream: Stream,
        bytes: Vec<u8>,
    },
}

/// Outputs that belong together (an EXR and its PNG, a plot's PNG and SVG), written all or
/// nothing: each is written in full first ([`add`](Self::add)), and only when all are complete
/// does [`commit`](Self::commit) put them in place. A failure before then leaves nothing; a
/// rename failing part way removes the outputs already renamed. Devices and FIFOs get their
/// bytes last, once every file is in place; what went into them cannot be taken back.
pub struct Batch<'a> {
    inputs: &'a Inputs,
    staged: Vec<Staged>,
}

impl<'a> Batch<'a> {
    /// An empty batch whose outputs may replace none of `inputs`.
    pub fn new(inputs: &'a Inputs) -> Self {
        Batch {
            inputs,
            staged: Vec::new(),
        }
    }

    /// Writes the output at `path` with `write`, which gets the [`Sink`] to write into; it is
    /// put in place by [`commit`](Self::commit).
    pub fn add<E: From<OutputError>>(
        &mut self,
        path: &Path,
        write: impl FnOnce(&mut Sink) -> Result<(), E>,
    ) -> Result<(), E> {
        let to = match target(path, self.inputs)? {
            Target::Replace { file } => {
                let tmp = temp_file(folder(&file)).map_err(|e| OutputError::Io {
                    path: path.to_owned(),
                    action: "create a temporary file beside it",
                    source: e,
                })?;
                SinkTo::File {
                    file,
                    tmp: BufWriter::new(tmp),
                }
            }
            Target::Stream(stream) => SinkTo::Memory {
                stream,
                bytes: Cursor::new(Vec::new()),
            },
        };
        let mut sink = Sink {
            path: path.to_owned(),
            to,
        };
        write(&mut sink)?;
        let staged = match sink.to {
            SinkTo::File { file, tmp } => {
                let tmp = tmp
                    .into_inner()
                    .map_err(|e| io_error(path, "write")(e.into_error()))?;
                tmp.as_file().sync_all().map_err(io_error(path, "sync"))?;
                Staged::Replace {
                    path: path.to_owned(),
                    file,
                    tmp,
                }
            }
            SinkTo::Memory { stream, bytes } => Staged::Stream {
                path: path.to_owned(),
                stream,
                bytes: bytes.into_inner(),
            },
        };
        self.staged.push(staged);
        Ok(())
    }

    /// Puts every output in place: opens the devices and FIFOs (refusing a FIFO without a
    /// reader), renames the files over their targets and syncs their folders, then writes the
    /// devices and FIFOs.
    pub fn commit(self) -> Result<(), OutputError> {
        let mut streams = Vec::new();
        let mut renames = Vec::new();
        for staged in self.staged {
            match staged {
                Staged::Stream {
                    path,
                    stream,
                    bytes,
                } => {
                    // Checked again: what the path names may have changed while it was written.
                    if target(&path, self.inputs)? != Target::Stream(stream) {
                        return Err(OutputError::Changed { path });
                    }
                    let file = open_stream(&path, stream)?;
                    streams.push((path, file, bytes));
                }
                Staged::Replace { path, file, tmp } => {
                    // Checked again: what the path names may have changed while it was written.
                    if target(&path, self.inputs)? != (Target::Replace { file: file.clone() }) {
                        return Err(OutputError::Changed { path });
                    }
                    renames.push((path, file, tmp));
                }
            }
        }
        let mut placed: Vec<PathBuf> = Vec::new();
        for (path, file, tmp) in renames {
            if let Err(e) = tmp.persist(&file) {
                for p in &placed {
                    let _ = std::fs::remove_file(p);
                }
                // The bare io::Error: the PersistError would hold the temporary file (and so
                // leave it behind) as long as the error lives.
                return Err(io_error(&path, "rename the finished file into place")(
                    e.error,
                ));
            }
            placed.push(file);
        }
        let mut folders: Vec<&Path> = placed.iter().map(|f| folder(f)).collect();
        folders.sort();
        folders.dedup();
        for dir in folders {
            sync_folder(dir)?;
        }
        for (path, mut file, bytes) in streams {
            file.write_all(&bytes)
                .and_then(|()| file.flush())
                .map_err(io_error(&path, "write"))?;
        }
        Ok(())
    }
}

/// Syncs a folder, so that a rename in it survives a crash.
fn sync_folder(dir: &Path) -> Result<(), OutputError> {
    let synced = File::open(dir).and_then(|f| f.sync_all());
    match synced {
        // Some file systems (network, FUSE) cannot sync a folder; the file itself is synced.
        Err(e) if e.kind() == std::io::ErrorKind::InvalidInput => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::Unsupported => Ok(()),
        r => r.map_err(|e| OutputError::Io {
            path: dir.to_owned(),
            action: "sync the folder",
            source: e,
        }),
    }
}

/// Opens a [`Target::Stream`] for writing, at its end and without blocking: a FIFO without a
/// reader is refused instead of waited on. Writes into it then block as usual. Opened without
/// `O_CREAT`, so nothing is made where nothing was.
#[cfg(unix)]
fn open_stream(path: &Path, stream: Stream) -> Result<File, OutputError> {
    use std::os::unix::fs::OpenOptionsExt;
    use std::os::unix::io::{AsRawFd, FromRawFd};
    let file = match stream {
        Stream::Descriptor(fd) => {
            // SAFETY: F_DUPFD_CLOEXEC touches no memory; it fails cleanly on a closed `fd`.
            let copy = unsafe { libc::fcntl(fd, libc::F_DUPFD_CLOEXEC, 0) };
            if copy < 0 {
                return Err(io_error(path, "open")(std::io::Error::last_os_error()));
            }
            // SAFETY: `copy` is a new descriptor that nothing else owns.
            return Ok(unsafe { File::from_raw_fd(copy) });
        }
        Stream::Path => std::fs::OpenOptions::new()
            .append(true)
            .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
            .open(path)
            .map_err(|e| match e.raw_os_error() {
                Some(libc::ENXIO) => OutputError::NoReader {
                    path: path.to_owned(),
                },
                _ => io_error(path, "open")(e),
            })?,
    };
    let raw = file.as_raw_fd();
    // SAFETY: `raw` is the open descriptor `file` owns for the duration of both calls; F_GETFL
    // and F_SETFL read and set its status flags and touch no memory.
    let blocking = unsafe {
        let flags = libc::fcntl(raw, libc::F_GETFL);
        flags >= 0 && libc::fcntl(raw, libc::F_SETFL, flags & !libc::O_NONBLOCK) >= 0
    };
    if !blocking {
        return Err(io_error(path, "open")(std::io::Error::last_os_error()));
    }
    Ok(file)
}

#[cfg(not(unix))]
fn open_stream(path: &Path, _: Stream) -> Result<File, OutputError> {
    Err(OutputError::Unwritable {
        path: path.to_owned(),
        kind: "special file",
    })
}

/// Writes one output at `path` with `write` ([`Batch`] of one).
pub fn write<E: From<OutputError>>(
    path: &Path,
    inputs: &Inputs,
    write: impl FnOnce(&mut Sink) -> Result<(), E>,
) -> Result<(), E> {
    let mut batch = Batch::new(inputs);
    batch.add(path, write)?;
    Ok(batch.commit()?)
}

/// Writes `bytes` to `path` ([`write`]).
pub fn write_bytes(path: &Path, inputs: &Inputs, bytes: &[u8]) -> Result<(), OutputError> {
    write(path, inputs, |sink| {
        sink.write_all(bytes).map_err(io_error(path, "write"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_util::files_in;

    #[cfg(unix)]
    fn mkfifo(path: &Path) {
        let made = std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .unwrap();
        assert!(made.success());
    }

    #[test]
    fn files_are_replaced_and_links_followed_to_the_file_they_name() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let none = Inputs::default();
        write_bytes(&d.join("a.csv"), &none, b"one").unwrap();
        write_bytes(&d.join("a.csv"), &none, b"two").unwrap();
        assert_eq!(std::fs::read(d.join("a.csv")).unwrap(), b"two");
        #[cfg(unix)]
        {
            std::fs::create_dir(d.join("real")).unwrap();
            std::fs::write(d.join("real/target.csv"), "old").unwrap();
            std::os::unix::fs::symlink("real/target.csv", d.join("link.csv")).unwrap();
            write_bytes(&d.join("link.csv"), &none, b"new").unwrap();
            assert!(std::fs::symlink_metadata(d.join("link.csv"))
                .unwrap()
                .file_type()
                .is_symlink());
            assert_eq!(std::fs::read(d.join("real/target.csv")).unwrap(), b"new");
            // A link to nothing yet: the file it names is created, beside itself.
            std::os::unix::fs::symlink("real/later.csv", d.join("dangling.csv")).unwrap();
            write_bytes(&d.join("dangling.csv"), &none, b"made").unwrap();
            assert_eq!(std::fs::read(d.join("real/later.csv")).unwrap(), b"made");
            assert_eq!(files_in(&d.join("real")), ["later.csv", "target.csv"]);
        }
        assert_eq!(
            files_in(d).iter().filter(|n| n.starts_with('.')).count(),
            0,
            "temporary files left"
        );
    }

    #[test]
    fn a_failed_batch_leaves_nothing_and_directories_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let none = Inputs::default();
        let mut batch = Batch::new(&none);
        batch
            .add(&d.join("a.png"), |s| {
                s.write_all(b"a")
                    .map_err(io_error(&d.join("a.png"), "write"))
            })
            .unwrap();
        let failed: Result<(), OutputError> = batch.add(&d.join("b.svg"), |s| {
            Err(OutputError::Changed {
                path: s.path().to_owned(),
            })
        });
        assert!(failed.is_err());
        drop(batch);
        assert!(files_in(d).is_empty(), "{:?}", files_in(d));
        std::fs::create_dir(d.join("taken.csv")).unwrap();
        let err = write_bytes(&d.join("taken.csv"), &none, b"x").unwrap_err();
        assert!(matches!(err, OutputError::Directory { .. }), "{err}");
        assert!(err.to_string().contains("taken.csv"), "{err}");
    }

    #[test]
    fn an_input_is_refused_under_any_name() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::create_dir(d.join("sub")).unwrap();
        std::fs::write(d.join("scene.ron"), "scene").unwrap();
        let inputs: Inputs = [d.join("scene.ron")].into_iter().collect();
        let mut names = vec![d.join("scene.ron"), d.join("sub/../scene.ron")];
        #[cfg(unix)]
        {
            std::fs::hard_link(d.join("scene.ron"), d.join("hard.csv")).unwrap();
            std::os::unix::fs::symlink("scene.ron", d.join("soft.csv")).unwrap();
            names.extend([d.join("hard.csv"), d.join("soft.csv")]);
        }
        for name in names {
            let err = write_bytes(&name, &inputs, b"x").unwrap_err();
            assert!(matches!(err, OutputError::Input { .. }), "{err}");
            let msg = err.to_string();
            assert!(
                msg.contains("an input") && msg.contains("scene.ron"),
                "{msg}"
            );
            assert_eq!(std::fs::read(d.join("scene.ron")).unwrap(), b"scene");
        }
        write_bytes(&d.join("other.csv"), &inputs, b"fine").unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn devices_and_fifos_are_written_into_never_replaced() {
        use std::io::Read;
        use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let none = Inputs::default();
        // A link to /dev/null: streamed into, the link and the device stay as they were.
        std::os::unix::fs::symlink("/dev/null", d.join("null.csv")).unwrap();
        write_bytes(&d.join("null.csv"), &none, b"gone").unwrap();
        assert!(std::fs::symlink_metadata(d.join("null.csv"))
            .unwrap()
            .file_type()
            .is_symlink());
        assert!(std::fs::metadata("/dev/null")
            .unwrap()
            .file_type()
            .is_char_device());
        // A FIFO nobody reads is refused at once; with a reader, the reader gets the bytes.
        let fifo = d.join("fifo.csv");
        mkfifo(&fifo);
        let err = write_bytes(&fifo, &none, b"lost").unwrap_err();
        assert!(matches!(err, OutputError::NoReader { .. }), "{err}");
        let mut reader = std::fs::OpenOptions::new()
            .read(true)
            .custom_flags(libc::O_NONBLOCK)
            .open(&fifo)
            .unwrap();
        std::os::unix::fs::symlink("fifo.csv", d.join("to_fifo.csv")).unwrap();
        write_bytes(&d.join("to_fifo.csv"), &none, b"through").unwrap();
        let mut got = Vec::new();
        reader.read_to_end(&mut got).unwrap();
        assert_eq!(got, b"through");
        assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());
        // A socket is refused by name.
        let socket = d.join("socket.csv");
        let _listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
        let err = write_bytes(&socket, &none, b"x").unwrap_err();
        assert!(err.to_string().contains("is a socket"), "{err}");
        assert!(std::fs::metadata(&socket).unwrap().file_type().is_socket());
        assert_eq!(
            files_in(d),
            ["fifo.csv", "null.csv", "socket.csv", "to_fifo.csv"]
        );
    }

    #[cfg(unix)]
    #[test]
    fn files_open_through_proc_are_appended_to_not_replaced() {
        use std::os::unix::fs::MetadataExt;
        use std::os::unix::io::AsRawFd;
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::write(d.join("log.txt"), "header\n").unwrap();
        let held = std::fs::OpenOptions::new()
            .append(true)
            .open(d.join("log.txt"))
            .unwrap();
        let inode = held.metadata().unwrap().ino();
        // As `/dev/stdout` names a redirected stdout: directly, and through a link of ours.
        let proc = PathBuf::from(format!("/proc/self/fd/{}", held.as_raw_fd()));
        std::os::unix::fs::symlink(&proc, d.join("out.csv")).unwrap();
        write_bytes(&proc, &Inputs::default(), b"one\n").unwrap();
        write_bytes(&d.join("out.csv"), &Inputs::default(), b"two\n").unwrap();
        assert_eq!(
            std::fs::read_to_string(d.join("log.txt")).unwrap(),
            "header\none\ntwo\n"
        );
        assert_eq!(std::fs::metadata(d.join("log.txt")).unwrap().ino(), inode);
        // Another process's descriptor is opened again, at the file's end.
        let mut child = std::process::Command::new("sleep")
            .arg("30")
            .stdout(held.try_clone().unwrap())
            .spawn()
            .unwrap();
        let theirs = PathBuf::from(format!("/proc/{}/fd/1", child.id()));
        let written = write_bytes(&theirs, &Inputs::default(), b"three\n");
        child.kill().unwrap();
        child.wait().unwrap();
        written.unwrap();
        assert_eq!(
            std::fs::read_to_string(d.join("log.txt")).unwrap(),
            "header\none\ntwo\nthree\n"
        );
        // The open file is an input: refused.
        let inputs: Inputs = [d.join("log.txt")].into_iter().collect();
        let err = write_bytes(&proc, &inputs, b"x").unwrap_err();
        assert!(matches!(err, OutputError::Input { .. }), "{err}");
        assert_eq!(files_in(d), ["log.txt", "out.csv"]);
    }
}
