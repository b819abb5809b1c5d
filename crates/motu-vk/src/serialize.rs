//! Serialised acceleration structures (`VK_COPY_ACCELERATION_STRUCTURE_MODE_SERIALIZE_KHR`):
//! what the streamer's structure cache keeps of a built BLAS, in host memory and on disk, and
//! turns back into a structure by copy instead of a rebuild.
//!
//! A serialised structure is opaque bytes whose header the spec fixes: the driver UUID (16
//! bytes), the compatibility data (16; together what
//! `vkGetDeviceAccelerationStructureCompatibilityKHR` judges), the serialised size (u64), the
//! size the deserialised structure needs (u64), then a handle count and handles (TLASes only).

use ash::vk;

use crate::accel::AsTarget;
use crate::command::CommandRecorder;
use crate::context::Context;
use crate::error::{Result, VkError};
use crate::memory::DeviceAddress;
use crate::structure::SizeQueries;

/// Bytes of the serialisation header this layer reads: the version data (32), the serialised
/// size and the deserialised size.
pub const SERIALIZED_HEADER_BYTES: usize = 48;

/// Serialised buffers and their sources' addresses: 256-byte aligned (the spec asks for 256
/// of `dst.deviceAddress` in a serialising copy and of `src.deviceAddress` in deserialising).
pub const SERIALIZED_ALIGNMENT: u64 = 256;

/// What a serialised structure's header says (see the module docs), `None` when `blob` is too
/// short to hold one.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SerializedHeader {
    /// Driver UUID and compatibility data.
    pub version_data: [u8; 32],
    pub serialized_bytes: u64,
    /// What `AccelStruct::new` must be given to deserialise into.
    pub deserialized_bytes: u64,
}

impl SerializedHeader {
    pub fn read(blob: &[u8]) -> Option<SerializedHeader> {
        let head = blob.get(..SERIALIZED_HEADER_BYTES)?;
        let u64_at = |at: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&head[at..at + 8]);
            u64::from_le_bytes(b)
        };
        let mut version_data = [0u8; 32];
        version_data.copy_from_slice(&head[..32]);
        Some(SerializedHeader {
            version_data,
            serialized_bytes: u64_at(32),
            deserialized_bytes: u64_at(40),
        })
    }
}

impl Context {
    /// Whether this device can deserialise a structure whose header starts with
    /// `version_data` (driver UUID and compatibility data): an entry of another driver, device
    /// or driver version is refused here, never handed to the driver.
    pub fn acceleration_structure_compatible(&self, version_data: &[u8; 32]) -> Result<bool> {
        let accel = self.accel_device()?;
        let info = vk::AccelerationStructureVersionInfoKHR::default().version_data(version_data);
        // SAFETY: `version_data` is 2 * VK_UUID_SIZE bytes, as the structure requires; the
        // device has the AS extension (accel_device checked).
        let compat = unsafe { accel.get_device_acceleration_structure_compatibility(&info) };
        Ok(compat == vk::AccelerationStructureCompatibilityKHR::COMPATIBLE)
    }

    /// A string naming the device and its driver build, for keys of caches that hold
    /// device-specific data (the compatibility check still decides).
    pub fn driver_identity(&self) -> String {
        let i = &self.shared.info;
        format!(
            "{}|{:08x}:{:08x}|{}|{}|{}",
            i.name, i.vendor_id, i.device_id, i.driver_name, i.driver_info, i.driver_version
        )
    }
}

impl CommandRecorder<'_> {
    /// Resets `queries` (made by [`SizeQueries::serialization`]) and writes the serialised
    /// sizes of `structures` (complete: record a barrier after their builds or copies) into
    /// its first queries, in order.
    pub fn write_serialization_sizes(
        &mut self,
        structures: &[AsTarget],
        queries: &SizeQueries,
    ) -> Result<()> {
        self.write_structure_properties(
            structures,
            queries,
            vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_SIZE_KHR,
        )
    }

    /// Serialises `src` to `dst` (a buffer with device-address usage holding its serialised
    /// size, 256-byte aligned; see [`SERIALIZED_ALIGNMENT`]).
    pub fn serialize_acceleration_structure(
        &mut self,
        src: AsTarget,
        dst: DeviceAddress,
    ) -> Result<()> {
        self.check_alignment("serialising into", dst)?;
        let accel = self.ctx().accel_device()?;
        let info = vk::CopyAccelerationStructureToMemoryInfoKHR::default()
            .src(src.0)
            .dst(vk::DeviceOrHostAddressKHR {
                device_address: dst.0,
            })
            .mode(vk::CopyAccelerationStructureModeKHR::SERIALIZE);
        // SAFETY: recording state; the structure and the destination buffer live until the
        // submission was waited on (the caller's contract, module docs of `command`); the
        // destination holds the size a serialisation-size query reported.
        unsafe { accel.cmd_copy_acceleration_structure_to_memory(self.raw_cmd(), &info) };
        Ok(())
    }

    /// Deserialises the serialised structure at `src` into `dst` (a structure made with the
    /// header's `deserialized_bytes`, on a device the header's version data is compatible
    /// with: [`Context::acceleration_structure_compatible`]).
    pub fn deserialize_acceleration_structure(
        &mut self,
        src: DeviceAddress,
        dst: AsTarget,
    ) -> Result<()> {
        self.check_alignment("deserialising from", src)?;
        let accel = self.ctx().accel_device()?;
        let info = vk::CopyMemoryToAccelerationStructureInfoKHR::default()
            .src(vk::DeviceOrHostAddressConstKHR {
                device_address: src.0,
            })
            .dst(dst.0)
            .mode(vk::CopyAccelerationStructureModeKHR::DESERIALIZE);
        // SAFETY: recording state; the source buffer and the structure live until the
        // submission was waited on (the caller's contract); the caller checked compatibility
        // and sized the structure from the header.
        unsafe { accel.cmd_copy_memory_to_acceleration_structure(self.raw_cmd(), &info) };
        Ok(())
    }

    fn check_alignment(&self, what: &str, at: DeviceAddress) -> Result<()> {
        if at.0 % SERIALIZED_ALIGNMENT != 0 {
            return Err(VkError::InvalidRequest(format!(
                "{}: {what} address {:#x}, not {SERIALIZED_ALIGNMENT}-byte aligned",
                self.label(),
                at.0
            )));
        }
        Ok(())
    }
}
