//! `motu devices`: what every Vulkan device offers, as JSON or a table.

use std::fmt::Write as _;

use crate::capabilities::{self, Caps, HeapReport, PhysicalInfo};
use crate::error::Result;
use crate::instance::{version_string, InstanceShared, ValidationRequest};
use crate::limits::{LimitOverrides, Limits};

/// One device as `motu devices` shows it (the JSON is `motu_render::stats::DeviceReport`).
/// Limits include env overrides (listed in `limit_overrides`), so the report shows what motu
/// will actually use.
#[derive(Clone, Debug)]
pub struct DeviceReport {
    /// Index for `--device N` / `MOTU_DEVICE`.
    pub index: usize,
    pub name: String,
    /// `driver_name driver_info (version)`, e.g. `llvmpipe Mesa 25.0.7 (LLVM 15.0.6) (0.0.1)`.
    pub driver: String,
    pub driver_name: String,
    pub driver_info: String,
    pub driver_version: String,
    pub vendor_id: u32,
    pub device_id: u32,
    pub device_type: &'static str,
    /// The device's own API version (motu uses at most 1.3).
    pub api_version: String,
    /// Whether motu can open it, and if not, why.
    pub usable: bool,
    pub unusable_reason: Option<String>,
    pub acceleration_structure: bool,
    pub ray_pipeline: bool,
    pub ray_query: bool,
    pub buffer_device_address: bool,
    pub memory_budget_ext: bool,
    pub caps: Caps,
    pub limits: Limits,
    pub heaps: Vec<HeapReport>,
    /// Names of limits lowered by `MOTU_MAX_*` environment overrides.
    pub limit_overrides: Vec<&'static str>,
}

/// Lists every Vulkan device (no validation, nothing opened). Errors say what to install:
/// [`VkError::LoaderMissing`] without `libvulkan1`, [`VkError::NoDevice`] without a driver.
///
/// [`VkError::LoaderMissing`]: crate::VkError::LoaderMissing
/// [`VkError::NoDevice`]: crate::VkError::NoDevice
pub fn list_devices() -> Result<Vec<DeviceReport>> {
    let overrides = LimitOverrides::from_env()?;
    let inst = InstanceShared::new(ValidationRequest::Off)?;
    let infos = capabilities::enumerate(&inst.instance, inst.api_version)?;
    Ok(infos
        .iter()
        .map(|info| {
            let heaps = capabilities::heaps(&inst.instance, info.handle, info.caps.memory_budget);
            DeviceReport::from_info(info, heaps, &overrides)
        })
        .collect())
}

impl DeviceReport {
    pub(crate) fn from_info(
        info: &PhysicalInfo,
        heaps: Vec<HeapReport>,
        overrides: &LimitOverrides,
    ) -> Self {
        let mut limits = info.limits.clone();
        let lowered = overrides.apply(&mut limits);
        let driver_version = info.driver_version_string();
        let driver = format!(
            "{} {} ({})",
            info.driver_name, info.driver_info, driver_version
        )
        .trim()
        .to_string();
        let unusable_reason = info.unusable_reason();
        DeviceReport {
            index: info.index,
            name: info.name.clone(),
            driver,
            driver_name: info.driver_name.clone(),
            driver_info: info.driver_info.clone(),
            driver_version,
            vendor_id: info.vendor_id,
            device_id: info.device_id,
            device_type: info.device_type,
            api_version: version_string(info.device_api_version),
            usable: unusable_reason.is_none(),
            unusable_reason,
            acceleration_structure: info.caps.acceleration_structure,
            ray_pipeline: info.caps.ray_pipeline,
            ray_query: info.caps.ray_query,
            buffer_device_address: info.caps.buffer_device_address,
            memory_budget_ext: info.caps.memory_budget,
            caps: info.caps.clone(),
            limits,
            heaps,
            limit_overrides: lowered,
        }
    }

    /// Human-readable view for `motu devices` without `--json`.
    pub fn to_table_string(&self) -> String {
        let mut s = String::new();
        let yn = |b: bool| if b { "yes" } else { "no" };
        let l = &self.limits;
        let _ = writeln!(
            s,
            "device {}: {} ({})",
            self.index, self.name, self.device_type
        );
        let mut rows: Vec<(&str, String)> = vec![
            ("driver", self.driver.clone()),
            ("vulkan", self.api_version.clone()),
        ];
        if let Some(reason) = &self.unusable_reason {
            rows.push(("UNUSABLE", reason.clone()));
        }
        rows.extend([
            ("ray_pipeline", yn(self.ray_pipeline).to_string()),
            ("ray_query", yn(self.ray_query).to_string()),
            (
                "acceleration_structure",
                yn(self.acceleration_structure).to_string(),
            ),
            (
                "buffer_device_address",
                yn(self.buffer_device_address).to_string(),
            ),
            ("memory_budget_ext", yn(self.memory_budget_ext).to_string()),
            ("max_instance_count", l.max_instance_count.to_string()),
            ("max_primitive_count", l.max_primitive_count.to_string()),
            ("max_geometry_count", l.max_geometry_count.to_string()),
            (
                "max_memory_allocation_count",
                l.max_memory_allocation_count.to_string(),
            ),
            (
                "max_memory_allocation_size",
                bytes(l.max_memory_allocation_size),
            ),
            (
                "max_storage_buffer_range",
                bytes(u64::from(l.max_storage_buffer_range)),
            ),
            (
                "max_buffer_size",
                l.max_buffer_size.map_or_else(|| "-".into(), bytes),
            ),
            (
                "as_scratch_alignment",
                l.min_acceleration_structure_scratch_offset_alignment
                    .to_string(),
            ),
            (
                "shader_group_handle",
                format!(
                    "size {} / base align {} / handle align {}",
                    l.shader_group_handle_size,
                    l.shader_group_base_alignment,
                    l.shader_group_handle_alignment
                ),
            ),
            (
                "max_ray_recursion_depth",
                l.max_ray_recursion_depth.to_string(),
            ),
            (
                "max_ray_hit_attribute_size",
                l.max_ray_hit_attribute_size.to_string(),
            ),
            (
                "max_ray_dispatch_invocations",
                l.max_ray_dispatch_invocation_count.to_string(),
            ),
            (
                "timestamps",
                if l.timestamp_valid_bits > 0 {
                    format!(
                        "{} bits, {} ns/tick",
                        l.timestamp_valid_bits, l.timestamp_period_ns
                    )
                } else {
                    "no".into()
                },
            ),
        ]);
        for h in &self.heaps {
            let budget = match (h.budget_bytes, h.usage_bytes) {
                (Some(b), Some(u)) => format!(", budget {}, used {}", bytes(b), bytes(u)),
                _ => String::new(),
            };
            rows.push((
                "heap",
                format!(
                    "#{} {}{}{}",
                    h.index,
                    bytes(h.size_bytes),
                    if h.device_local { " device-local" } else { "" },
                    budget
                ),
            ));
        }
        if !self.limit_overrides.is_empty() {
            rows.push(("lowered by env", self.limit_overrides.join(", ")));
        }
        let width = rows.iter().map(|(k, _)| k.len()).max().unwrap_or(0);
        for (k, v) in rows {
            let _ = writeln!(s, "  {k:<width$}  {v}");
        }
        s
    }
}

/// `2.00 GiB (2147483648)`: readable and exact.
fn bytes(n: u64) -> String {
    match motu_alloc::binary_scale(n) {
        (_, "B") => format!("{n} B"),
        (v, unit) => format!("{v:.2} {unit} ({n})"),
    }
}

#[cfg(test)]
mod tests;
