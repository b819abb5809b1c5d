//! GPU timestamps (for `motu bench`, build and trace timings).

use std::sync::Arc;

use ash::vk;

use crate::context::{Context, DeviceShared};
use crate::error::{Result, VkError};

/// A timestamp query pool. Record `reset_queries` then `write_timestamp`s, submit, then read.
pub struct TimestampQueries {
    shared: Arc<DeviceShared>,
    pool: vk::QueryPool,
    count: u32,
}

impl std::fmt::Debug for TimestampQueries {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TimestampQueries")
            .field("count", &self.count)
            .finish()
    }
}

impl TimestampQueries {
    pub fn new(ctx: &Context, count: u32) -> Result<TimestampQueries> {
        if !ctx.caps().timestamps {
            return Err(VkError::MissingFeature {
                what: "timestamps".into(),
                details: format!(
                    "{}: the queue has timestampValidBits = 0",
                    ctx.device_name()
                ),
            });
        }
        if count == 0 {
            return Err(VkError::InvalidRequest("zero timestamp queries".into()));
        }
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::TIMESTAMP)
            .query_count(count);
        // SAFETY: valid create info for this device.
        let pool = unsafe { ctx.shared.device.create_query_pool(&info, None) }
            .map_err(VkError::vk("vkCreateQueryPool"))?;
        Ok(TimestampQueries {
            shared: Arc::clone(&ctx.shared),
            pool,
            count,
        })
    }

    pub fn count(&self) -> u32 {
        self.count
    }

    pub(crate) fn handle(&self) -> vk::QueryPool {
        self.pool
    }

    /// Raw ticks of every query, waiting for results. Call after the submission that wrote
    /// them; every query must have been written.
    pub fn read_ticks(&self) -> Result<Vec<u64>> {
        let mut ticks = vec![0u64; self.count as usize];
        // SAFETY: the pool is live; the output slice has one u64 per query (64-bit flag set).
        unsafe {
            self.shared.device.get_query_pool_results(
                self.pool,
                0,
                &mut ticks,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(VkError::vk("vkGetQueryPoolResults"))?;
        let bits = self.shared.limits.timestamp_valid_bits;
        if bits < 64 {
            let mask = (1u64 << bits) - 1;
            ticks.iter_mut().for_each(|t| *t &= mask);
        }
        Ok(ticks)
    }

    /// Nanoseconds between queries `from` and `to` (handles counter wrap-around).
    pub fn elapsed_ns(&self, ticks: &[u64], from: u32, to: u32) -> Result<f64> {
        let (Some(&a), Some(&b)) = (ticks.get(from as usize), ticks.get(to as usize)) else {
            return Err(VkError::InvalidRequest(format!(
                "timestamp indices {from}, {to} out of range ({})",
                ticks.len()
            )));
        };
        let bits = self.shared.limits.timestamp_valid_bits;
        let delta = if bits >= 64 {
            b.wrapping_sub(a)
        } else {
            b.wrapping_sub(a) & ((1u64 << bits) - 1)
        };
        Ok(delta as f64 * f64::from(self.shared.limits.timestamp_period_ns))
    }
}

impl Drop for TimestampQueries {
    fn drop(&mut self) {
        // SAFETY: created from this device; recorder borrows guarantee no pending use.
        unsafe { self.shared.device.destroy_query_pool(self.pool, None) };
    }
}
