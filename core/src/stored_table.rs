//! Tables kept on disk between runs, in a folder the front end chooses
//! ([`crate::prepare::Preparation::with_table_dir`]): a precomputation that takes seconds and
//! depends only on a few numbers is stored once and read back by later runs.
//!
//! A table is stored under `<kind>-v<version>-<hash of its key>.table`, written through
//! [`crate::output_file`] (a temporary file synced and renamed into place, so a reader never
//! sees half of one and two processes writing the same table leave one whole). The file holds
//!
//! | bytes | what |
//! |---|---|
//! | 8 | magic `TRESSTBL` |
//! | 4 | container format version ([`FORMAT`]) |
//! | 4 + n | the kind's name (length, UTF-8) |
//! | 4 | the kind's version ([`StoredTable::VERSION`]) |
//! | 4 + n | the key's bytes, whole ([`StoredTable::key_bytes`]) |
//! | 8 + n | the payload ([`StoredTable::encode`]) |
//! | 8 | FNV-1a 64 of everything before it |
//!
//! all integers little-endian. A file is used only when every field matches what the run asks
//! for — the key compared whole, not by its hash — and the payload decodes to a table of the
//! expected sizes; any other file (truncated, corrupt, of another version or another key) is
//! ignored with a one-line warning and the table is built again and stored over it. Nothing
//! here panics on a file's contents.

use crate::output_file::{self, Inputs};
use std::path::{Path, PathBuf};

/// Version of the container layout above; a kind's own encoding has [`StoredTable::VERSION`].
pub const FORMAT: u32 = 1;
const MAGIC: &[u8; 8] = b"TRESSTBL";

/// A precomputed table that can be kept on disk.
pub trait StoredTable: Sized + Send + Sync + 'static {
    /// The in-memory key of the run's cache: exactly what shapes the table.
    type Key: std::hash::Hash + Eq + Send + Sync + 'static;
    /// Name of the kind, in file names and notes (`fur-medulla`): letters, digits and `-`.
    const KIND: &'static str;
    /// Version of the kind's encoding and of what its build computes: bumped whenever either
    /// changes, so that no run reads a table an older build computed differently.
    const VERSION: u32;
    /// The key as bytes, stored whole in the file and compared whole when it is read: every
    /// value that shapes the table (parameters, resolutions, sample counts).
    fn key_bytes(key: &Self::Key) -> Vec<u8>;
    /// Appends the table's bytes to `out`.
    fn encode(&self, out: &mut Vec<u8>);
    /// The table from bytes [`StoredTable::encode`] wrote, or why they are not one (wrong
    /// sizes, values out of range). Never panics.
    fn decode(bytes: &[u8]) -> Result<Self, String>;
}

/// FNV-1a, 64 bits: the file names' key hash and the files' checksum (stable across builds and
/// platforms, unlike `std`'s hasher).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The file in `dir` that holds `T`'s table for the key of bytes `key` ([`StoredTable::key_bytes`]).
pub fn path<T: StoredTable>(dir: &Path, key: &[u8]) -> PathBuf {
    dir.join(format!(
        "{}-v{}-{:016x}.table",
        T::KIND,
        T::VERSION,
        fnv1a64(key)
    ))
}

/// The whole file of `table` under the key of bytes `key`.
pub fn encode_file<T: StoredTable>(key: &[u8], table: &T) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&FORMAT.to_le_bytes());
    put_bytes(&mut out, T::KIND.as_bytes());
    out.extend_from_slice(&T::VERSION.to_le_bytes());
    put_bytes(&mut out, key);
    let mut payload = Vec::new();
    table.encode(&mut payload);
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&payload);
    let sum = fnv1a64(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

fn put_bytes(out: &mut Vec<u8>, bytes: &[u8]) {
    out.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(bytes);
}

/// Reads a file's fields in order; every read checks the length left.
struct Reader<'a> {
    bytes: &'a [u8],
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: u64, what: &str) -> Result<&'a [u8], String> {
        match usize::try_from(n).ok().filter(|&n| n <= self.bytes.len()) {
            Some(n) => {
                let (head, rest) = self.bytes.split_at(n);
                self.bytes = rest;
                Ok(head)
            }
            None => Err(format!(
                "truncated: {what} needs {n} bytes, {} are left",
                self.bytes.len()
            )),
        }
    }

    fn u32(&mut self, what: &str) -> Result<u32, String> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self, what: &str) -> Result<u64, String> {
        let b = self.take(8, what)?;
        let mut a = [0; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    fn bytes(&mut self, what: &str) -> Result<&'a [u8], String> {
        let n = self.u32(what)?;
        self.take(u64::from(n), what)
    }
}

/// The table stored in `bytes` if they hold `T`'s table for the key of bytes `key`, or why not.
pub fn decode_file<T: StoredTable>(key: &[u8], bytes: &[u8]) -> Result<T, String> {
    if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
        return Err("not a tress table file".into());
    }
    let Some(body_len) = bytes.len().checked_sub(8).filter(|&n| n >= MAGIC.len()) else {
        return Err("truncated: no checksum".into());
    };
    let mut r = Reader {
        bytes: &bytes[MAGIC.len()..],
    };
    let format = r.u32("the format version")?;
    if format != FORMAT {
        return Err(format!(
            "container format {format}, this build reads {FORMAT}"
        ));
    }
    let kind = r.bytes("the kind")?;
    if kind != T::KIND.as_bytes() {
        return Err(format!(
            "holds a {} table, not {}",
            String::from_utf8_lossy(kind),
            T::KIND
        ));
    }
    let version = r.u32("the version")?;
    if version != T::VERSION {
        return Err(format!(
            "version {version}, this build reads version {}",
            T::VERSION
        ));
    }
    if r.bytes("the key")? != key {
        return Err("its key differs from the table's asked for".into());
    }
    let n = r.u64("the payload's length")?;
    let payload = r.take(n, "the payload")?;
    let stored = r.u64("the checksum")?;
    if !r.bytes.is_empty() {
        return Err(format!("{} bytes past the checksum", r.bytes.len()));
    }
    let sum = fnv1a64(&bytes[..body_len]);
    if stored != sum {
        return Err(format!(
            "checksum {stored:016x}, its contents give {sum:016x}"
        ));
    }
    T::decode(payload)
}

/// What [`load`] found.
pub enum Loaded<T> {
    /// The table, read back.
    Table(T),
    /// No file for this key.
    Absent,
    /// A file that is not this table (unreadable, truncated, corrupt, of another version or
    /// key): why.
    Rejected(String),
}

/// The table stored at `path` for the key of bytes `key` ([`decode_file`]).
pub fn load<T: StoredTable>(path: &Path, key: &[u8]) -> Loaded<T> {
    match crate::files::read_regular(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Loaded::Absent,
        Err(e) => Loaded::Rejected(format!("cannot read it: {e}")),
        Ok(bytes) => match decode_file(key, &bytes) {
            Ok(t) => Loaded::Table(t),
            Err(why) => Loaded::Rejected(why),
        },
    }
}

/// Stores `table` at `path` for the key of bytes `key`, creating its folder if need be.
pub fn store<T: StoredTable>(path: &Path, key: &[u8], table: &T) -> Result<(), String> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("{}: cannot create the folder: {e}", dir.display()))?;
    }
    output_file::write_bytes(path, &Inputs::default(), &encode_file(key, table)).map_err(|e| {
        let mut text = e.to_string();
        let mut source = std::error::Error::source(&e);
        while let Some(s) = source {
            text.push_str(&format!(": {s}"));
            source = s.source();
        }
        text
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    const K7: [u8; 4] = 7u32.to_le_bytes();

    /// A table of numbers keyed by a seed.
    #[derive(Debug, PartialEq)]
    pub(crate) struct Squares(pub Vec<u32>);

    impl StoredTable for Squares {
        type Key = u32;
        const KIND: &'static str = "squares";
        const VERSION: u32 = 3;
        fn key_bytes(key: &u32) -> Vec<u8> {
            key.to_le_bytes().to_vec()
        }
        fn encode(&self, out: &mut Vec<u8>) {
            self.0.iter().for_each(|v| out.extend(v.to_le_bytes()));
        }
        fn decode(bytes: &[u8]) -> Result<Self, String> {
            if bytes.len() != 16 {
                return Err(format!("{} bytes, not 16", bytes.len()));
            }
            Ok(Squares(
                bytes
                    .chunks_exact(4)
                    .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .collect(),
            ))
        }
    }

    #[test]
    fn a_file_reads_back_only_for_its_own_kind_version_and_key() {
        let t = Squares(vec![1, 4, 9, 16]);
        let file = encode_file(&K7, &t);
        assert_eq!(
            decode_file::<Squares>(&K7, &file),
            Ok(Squares(vec![1, 4, 9, 16]))
        );
        let err = |bytes: &[u8], key: [u8; 4]| decode_file::<Squares>(&key, bytes).unwrap_err();
        assert!(err(&file, 8u32.to_le_bytes()).contains("key differs"));
        // Every truncation, and every single flipped bit, is refused.
        for n in 0..file.len() {
            assert!(
                decode_file::<Squares>(&K7, &file[..n]).is_err(),
                "{n} bytes"
            );
        }
        for i in 0..file.len() * 8 {
            let mut bad = file.clone();
            bad[i / 8] ^= 1 << (i % 8);
            assert!(decode_file::<Squares>(&K7, &bad).is_err(), "bit {i}");
        }
        // Another version of the kind (the version follows magic, format and kind).
        let mut other = file.clone();
        let at = 8 + 4 + 4 + "squares".len();
        other[at] = 2;
        let body = other.len() - 8;
        let sum = fnv1a64(&other[..body]);
        other[body..].copy_from_slice(&sum.to_le_bytes());
        assert!(err(&other, K7).contains("version 2"));
        let mut longer = file.clone();
        longer.push(0);
        assert!(decode_file::<Squares>(&K7, &longer).is_err());
        assert!(err(b"TRESSTB", K7).contains("not a tress table"));
    }

    #[test]
    fn stored_tables_go_under_their_key_hash_and_come_back() {
        let dir = tempfile::tempdir().unwrap();
        let p = path::<Squares>(&dir.path().join("sub"), &K7);
        assert!(p.to_str().unwrap().ends_with(&format!(
            "squares-v3-{:016x}.table",
            fnv1a64(&7u32.to_le_bytes())
        )));
        assert!(matches!(load::<Squares>(&p, &K7), Loaded::Absent));
        store(&p, &K7, &Squares(vec![0, 1, 2, 3])).unwrap();
        assert!(matches!(load::<Squares>(&p, &K7), Loaded::Table(Squares(v)) if v == [0, 1, 2, 3]));
        assert!(matches!(
            load::<Squares>(&p, &8u32.to_le_bytes()),
            Loaded::Rejected(_)
        ));
    }
}
