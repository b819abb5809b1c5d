//! The per-pass parameter block the traversal shaders read (`StreamParams` of `common.glsl`)
//! and the size of the per-pixel state carried across passes: the GPU-facing layout that the
//! pass loop fills and the frame buffers size, kept below both.

use bytemuck::{Pod, Zeroable};

/// `StreamParams` of `common.glsl` (96 bytes).
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
#[repr(C)]
pub(super) struct StreamParams {
    /// u32 per BLAS: `4 × stamp + level` (seen 0, open 1, needed 2) of the latest pass.
    pub(super) blas_stamps: u64,
    /// u32 per BLAS: the latest stamp of a pass it was resident (walked) in.
    pub(super) walked: u64,
    pub(super) pixel_list: u64,
    pub(super) incomplete: u64,
    pub(super) stamp: u32,
    pub(super) full_count: u32,
    pub(super) list_count: u32,
    pub(super) blas_count: u32,
    /// u32 per BLAS: pixels of the pass whose nearest open structure it is (build priority).
    pub(super) requests: u64,
    /// [`CARRY_BYTES`] per pixel: the state carried across passes (`Carry` of
    /// `render_pixel.glsl`).
    pub(super) carry: u64,
    /// u32 global instance indices of the proxy clusters' members (a proxy PI record names
    /// its range), 0: no proxies.
    pub(super) cluster_members: u64,
    /// `[first, fan]` (u32 each) per BLAS and the boxes inside BLASes (`[f32; 6]` each, BLAS
    /// space) a ray must also enter to open one (`proxy_boxes.rs`); 0: none.
    pub(super) proxy_box_index: u64,
    pub(super) proxy_boxes: u64,
    /// [`STREAM_PROBE_PASS`] or 0, with a probe's pass-mark row stride `<<`
    /// [`STREAM_PASS_ROWS_SHIFT`].
    pub(super) flags: u32,
    pub(super) _pad: u32,
}

/// `STREAM_PROBE_PASS` of `common.glsl`: the pass probes the next frame's camera (every
/// pixel's rays run against what is resident and only mark what they meet).
pub(super) const STREAM_PROBE_PASS: u32 = 1;

/// `STREAM_PASS_ROWS_SHIFT` of `common.glsl`: `flags >> it` is the probe's pass-mark row
/// stride (0: none; `StreamOptions::pass_marks`).
pub(super) const STREAM_PASS_ROWS_SHIFT: u32 = 8;

/// The largest pass-mark row stride the flags hold (a stride at or above the image height
/// marks row 0 only, so larger ones mean the same).
pub(super) const MAX_PASS_ROWS: u32 = u32::MAX >> STREAM_PASS_ROWS_SHIFT;

/// Stamps stay below this (`STREAM_START_STAMP` of `common.glsl` + 1): a ray's payload keeps
/// its start stamp in the low 29 bits, and a stamp table `4 × stamp + level` in a u32.
pub(super) const STAMP_LIMIT: u32 = 1 << 29;

/// The `flags` of a probe pass marking what the rays of every `pass_rows`-th row pass.
pub(super) fn probe_flags(pass_rows: u32) -> u32 {
    STREAM_PROBE_PASS | pass_rows.min(MAX_PASS_ROWS) << STREAM_PASS_ROWS_SHIFT
}

/// Whether a stamp-table value is a pass-mark walk's mark of pass `stamp`
/// (`4 × stamp - 1`, `candidates.glsl`).
pub(super) fn passed_mark(value: u32, stamp: u32) -> bool {
    stamp > 0 && value == 4 * stamp - 1
}

/// Bytes of one pixel's `Carry` (`render_pixel.glsl`).
pub(super) const CARRY_BYTES: u64 = 176;

#[cfg(test)]
mod tests {
    use super::*;

    const COMMON: &str = include_str!("../../../../shaders/common.glsl");

    fn define(name: &str) -> u32 {
        let line = COMMON
            .lines()
            .find_map(|l| l.strip_prefix(&format!("#define {name} ")))
            .unwrap_or_else(|| panic!("common.glsl has no #define {name}"));
        let v = line
            .split_whitespace()
            .next()
            .unwrap()
            .trim_end_matches('u');
        match v.strip_prefix("0x") {
            Some(h) => u32::from_str_radix(h, 16).unwrap(),
            None => v.parse().unwrap(),
        }
    }

    /// `StreamParams` and its constants are written twice (here and in common.glsl): this
    /// keeps the fields' order and sizes and the constants equal.
    #[test]
    fn stream_params_match_common_glsl() {
        assert_eq!(define("STREAM_PROBE_PASS"), STREAM_PROBE_PASS);
        assert_eq!(define("STREAM_PASS_ROWS_SHIFT"), STREAM_PASS_ROWS_SHIFT);
        assert_eq!(define("STREAM_START_STAMP") + 1, STAMP_LIMIT);
        for bit in ["STREAM_GUARD_RAY", "STREAM_MARK_WALK", "STREAM_PASS_WALK"] {
            let b = define(bit);
            assert!(
                b.is_power_of_two() && b >= STAMP_LIMIT,
                "{bit} {b:#x} overlaps stamps"
            );
        }
        let body = COMMON
            .split("struct StreamParams {")
            .nth(1)
            .and_then(|s| s.split("};").next())
            .expect("common.glsl has struct StreamParams");
        let fields: Vec<(String, usize)> = body
            .lines()
            .filter_map(|l| {
                let l = l.split("//").next()?.trim();
                let (ty, name) = l.strip_suffix(';')?.split_once(' ')?;
                let size = match ty {
                    "uint64_t" => 8,
                    "uint" => 4,
                    other => panic!("StreamParams field type {other} not mirrored"),
                };
                Some((name.trim().to_string(), size))
            })
            .collect();
        let rust = [
            ("blas_stamps", 8),
            ("walked", 8),
            ("pixel_list", 8),
            ("incomplete", 8),
            ("stamp", 4),
            ("full_count", 4),
            ("list_count", 4),
            ("blas_count", 4),
            ("requests", 8),
            ("carry", 8),
            ("cluster_members", 8),
            ("proxy_box_index", 8),
            ("proxy_boxes", 8),
            ("flags", 4),
            ("_pad", 4),
        ];
        let glsl: Vec<(&str, usize)> = fields.iter().map(|(n, s)| (n.as_str(), *s)).collect();
        assert_eq!(glsl, rust);
        assert_eq!(
            std::mem::size_of::<StreamParams>(),
            rust.iter().map(|f| f.1).sum::<usize>()
        );
    }

    #[test]
    fn probe_flags_carry_the_pass_rows_and_passed_marks_are_one_below_the_pass() {
        assert_eq!(probe_flags(0), STREAM_PROBE_PASS);
        assert_eq!(probe_flags(3) >> STREAM_PASS_ROWS_SHIFT, 3);
        assert_eq!(
            probe_flags(u32::MAX) >> STREAM_PASS_ROWS_SHIFT,
            MAX_PASS_ROWS
        );
        assert_eq!(probe_flags(u32::MAX) & STREAM_PROBE_PASS, STREAM_PROBE_PASS);
        // Level 3 of the stamp before: above every mark of earlier passes, below this one's.
        assert!(passed_mark(4 * 7 - 1, 7));
        for level in 0..3 {
            assert!(!passed_mark(4 * 7 + level, 7));
            assert!(!passed_mark(4 * 6 + level, 7));
        }
        assert!(!passed_mark(0, 0));
    }
}
