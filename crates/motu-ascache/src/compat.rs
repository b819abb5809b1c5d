//! The caller's answer to "can this device use these serialized bytes?".

/// The bytes at the start of every serialized acceleration structure that say which driver
/// wrote it: Vulkan's serialization header begins with the `driverUUID` (16 bytes) and the
/// acceleration-structure compatibility identifier (16 bytes), which
/// `vkGetDeviceAccelerationStructureCompatibilityKHR` takes as its version data.
pub const SERIALIZED_HEADER_BYTES: usize = 32;

/// Answers whether the device can deserialize a blob written under `header` (the blob's first
/// [`SERIALIZED_HEADER_BYTES`]). The GPU layer asks
/// `vkGetDeviceAccelerationStructureCompatibilityKHR`; tests pass a closure.
///
/// A closure `Fn(&[u8; 32]) -> bool` is a `Compatibility`.
pub trait Compatibility {
    /// `true` when the device can deserialize a structure serialized under `header`.
    fn compatible(&self, header: &[u8; SERIALIZED_HEADER_BYTES]) -> bool;
}

impl<F: Fn(&[u8; SERIALIZED_HEADER_BYTES]) -> bool> Compatibility for F {
    fn compatible(&self, header: &[u8; SERIALIZED_HEADER_BYTES]) -> bool {
        self(header)
    }
}

/// Accepts every header: for tests, and for callers that check compatibility themselves.
#[derive(Debug, Clone, Copy, Default)]
pub struct AnyDevice;

impl Compatibility for AnyDevice {
    fn compatible(&self, _header: &[u8; SERIALIZED_HEADER_BYTES]) -> bool {
        true
    }
}

/// The serialization header at the start of `blob`, if it is long enough to have one.
pub fn serialized_header(blob: &[u8]) -> Option<&[u8; SERIALIZED_HEADER_BYTES]> {
    blob.get(..SERIALIZED_HEADER_BYTES)?.try_into().ok()
}

#[cfg(test)]
mod tests;
