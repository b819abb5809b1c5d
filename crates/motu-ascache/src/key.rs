//! Cache keys: 256 opaque bits the caller derives from everything a built structure depends on.

use std::fmt;

use xxhash_rust::xxh3::Xxh3;

/// The identity of one cached structure: 32 opaque bytes, the address of its entry in both
/// tiers and (as 64 hex digits) its file name on disk.
///
/// The cache never looks inside a key; two structures with the same key are the same
/// structure. Make keys with [`CacheKeyBuilder`] from *all* the inputs the built bytes depend
/// on (see its docs), never from a name or a position that could mean other content later.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct CacheKey(pub [u8; 32]);

/// Why a string is not a [`CacheKey`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum KeyParseError {
    /// The string is not 64 characters long.
    #[error("a cache key is 64 hex digits, got {0} characters")]
    Length(usize),
    /// A character is not a lowercase or uppercase hex digit.
    #[error("a cache key is 64 hex digits, found {0:?}")]
    Digit(char),
}

impl CacheKey {
    /// The key as 64 lowercase hex digits (its entry's file stem on disk).
    pub fn to_hex(&self) -> String {
        const DIGITS: &[u8; 16] = b"0123456789abcdef";
        let mut s = String::with_capacity(64);
        for b in self.0 {
            s.push(DIGITS[usize::from(b >> 4)] as char);
            s.push(DIGITS[usize::from(b & 15)] as char);
        }
        s
    }

    /// Parses 64 hex digits (either case), the inverse of [`to_hex`](Self::to_hex).
    pub fn from_hex(s: &str) -> Result<Self, KeyParseError> {
        if s.len() != 64 {
            return Err(KeyParseError::Length(s.chars().count()));
        }
        let mut out = [0u8; 32];
        let digit = |c: u8| -> Result<u8, KeyParseError> {
            (c as char)
                .to_digit(16)
                .map(|d| d as u8)
                .ok_or(KeyParseError::Digit(c as char))
        };
        for (i, pair) in s.as_bytes().chunks_exact(2).enumerate() {
            out[i] = (digit(pair[0])? << 4) | digit(pair[1])?;
        }
        Ok(Self(out))
    }
}

impl fmt::Display for CacheKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_hex())
    }
}

impl fmt::Debug for CacheKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "CacheKey({})", self.to_hex())
    }
}

/// Seeds of the two independent XXH3-128 streams whose digests make a key's two halves.
const SEEDS: [u64; 2] = [0x6d6f_7475_2d61_7363, 0x9e37_79b9_7f4a_7c15];

/// Field tags: each field is framed as `tag, [length,] bytes`, so a sequence of fields encodes
/// one way only (`bytes("ab"), bytes("c")` never hashes like `bytes("a"), bytes("bc")`, and a
/// `u64` never like 8 raw bytes).
mod tag {
    pub const BYTES: u8 = 1;
    pub const U32: u8 = 2;
    pub const U64: u8 = 3;
    pub const STR: u8 = 4;
}

/// Hashes a sequence of fields into a [`CacheKey`].
///
/// Feed it everything the built bytes depend on, in a fixed order (the *schema*):
/// - a format version of the caller's own (bump it when what is hashed, or how a structure is
///   built from it, changes: old entries then simply stop matching);
/// - the structure's content: its geometry records and the checksums of the mesh chunks they
///   read (content, not package paths: a re-imported identical package hits, a changed one
///   misses);
/// - the build flags and anything else that changes the built bytes;
/// - the device's identity (`driverUUID`, `deviceUUID`): the compatibility check
///   ([`Compatibility`](crate::Compatibility)) is the guard, but keying by device keeps two GPUs
///   sharing one cache directory from replacing each other's entries.
///
/// The domain string given to [`new`](Self::new) separates unrelated uses of the same bytes.
///
/// **Collisions.** The key is two XXH3-128 digests of the same framed stream under two
/// different seeds. XXH3 is not cryptographic: it is a fast, well-distributed hash, so for
/// accidental collisions each 128-bit half alone makes one negligible (about `n²/2¹²⁹` for `n`
/// entries: below 10⁻¹⁸ for a billion entries), and the second seed covers a structural
/// weakness of one stream. It does not resist *deliberate* collisions: the cache directory
/// must be trusted like the packages are (anyone who can write it can already hand the driver
/// arbitrary bytes). A collision would restore another structure, which is why every input
/// must be in the key.
#[derive(Clone)]
pub struct CacheKeyBuilder {
    streams: [Xxh3; 2],
}

impl fmt::Debug for CacheKeyBuilder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("CacheKeyBuilder").finish_non_exhaustive()
    }
}

impl CacheKeyBuilder {
    /// A builder for keys of one kind, named by `domain` (e.g. `"motu-gpu blas v1"`).
    pub fn new(domain: &str) -> Self {
        let mut b = Self {
            streams: SEEDS.map(Xxh3::with_seed),
        };
        b.str(domain);
        b
    }

    fn raw(&mut self, bytes: &[u8]) {
        for s in &mut self.streams {
            s.update(bytes);
        }
    }

    /// Adds a byte slice (framed by its length).
    pub fn bytes(&mut self, bytes: &[u8]) -> &mut Self {
        self.raw(&[tag::BYTES]);
        self.raw(&(bytes.len() as u64).to_le_bytes());
        self.raw(bytes);
        self
    }

    /// Adds a UTF-8 string (framed by its length).
    pub fn str(&mut self, s: &str) -> &mut Self {
        self.raw(&[tag::STR]);
        self.raw(&(s.len() as u64).to_le_bytes());
        self.raw(s.as_bytes());
        self
    }

    /// Adds a 32-bit integer.
    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.raw(&[tag::U32]);
        self.raw(&v.to_le_bytes());
        self
    }

    /// Adds a 64-bit integer.
    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.raw(&[tag::U64]);
        self.raw(&v.to_le_bytes());
        self
    }

    /// The key of everything added so far (the builder can go on: a key per prefix).
    pub fn finish(&self) -> CacheKey {
        let mut out = [0u8; 32];
        out[..16].copy_from_slice(&self.streams[0].digest128().to_le_bytes());
        out[16..].copy_from_slice(&self.streams[1].digest128().to_le_bytes());
        CacheKey(out)
    }
}

#[cfg(test)]
mod tests;
