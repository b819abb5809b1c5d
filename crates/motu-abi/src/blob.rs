//! A small tagged blob: a magic, little-endian lengths and a payload. The structure cache's
//! tables (`motu-gpu` stream plan and proxy boxes) and a package's `proxy_boxes` section
//! (`motu-compile`) are written with [`BlobWriter`] and read back with [`BlobReader`], which
//! refuses another magic, a cut blob and (at [`BlobReader::finish`]) trailing bytes.

/// Appends a magic, then whatever the caller writes, little-endian.
pub struct BlobWriter(Vec<u8>);

impl BlobWriter {
    /// A blob that starts with `magic`; `capacity` bytes reserved (a hint).
    pub fn new(magic: &[u8], capacity: usize) -> BlobWriter {
        let mut out = Vec::with_capacity(magic.len() + capacity);
        out.extend_from_slice(magic);
        BlobWriter(out)
    }

    pub fn u32(&mut self, v: u32) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }

    pub fn u64(&mut self, v: u64) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }

    /// A slice of `Pod` values as their bytes (the caller writes its length first when the
    /// reader cannot know it).
    pub fn pods<T: bytemuck::Pod>(&mut self, values: &[T]) -> &mut Self {
        self.0.extend_from_slice(bytemuck::cast_slice(values));
        self
    }

    pub fn finish(self) -> Vec<u8> {
        self.0
    }
}

/// Reads what a [`BlobWriter`] wrote; every read is `None` when the blob is cut short.
pub struct BlobReader<'a>(&'a [u8]);

impl<'a> BlobReader<'a> {
    /// `None` unless `blob` starts with `magic`.
    pub fn new(blob: &'a [u8], magic: &[u8]) -> Option<BlobReader<'a>> {
        blob.strip_prefix(magic).map(BlobReader)
    }

    pub fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.0.len() < n {
            return None;
        }
        let (head, tail) = self.0.split_at(n);
        self.0 = tail;
        Some(head)
    }

    pub fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }

    pub fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }

    /// `count` `Pod` values, copied out (the blob's bytes need not be aligned for `T`).
    pub fn pods<T: bytemuck::Pod>(&mut self, count: usize) -> Option<Vec<T>> {
        let bytes = self.take(count.checked_mul(std::mem::size_of::<T>())?)?;
        let mut out = vec![T::zeroed(); count];
        bytemuck::cast_slice_mut::<T, u8>(&mut out).copy_from_slice(bytes);
        Some(out)
    }

    /// Whether the next bytes are exactly `bytes` (consumed when they are).
    pub fn expect(&mut self, bytes: &[u8]) -> Option<()> {
        (self.take(bytes.len())? == bytes).then_some(())
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.0.len()
    }

    /// `Some` when everything was read: a blob with trailing bytes is not the one written.
    pub fn finish(self) -> Option<()> {
        self.0.is_empty().then_some(())
    }
}

#[cfg(test)]
mod tests;
