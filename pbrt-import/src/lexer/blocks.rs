//! Numeric arrays read 64 bytes at a time (issue 48 item 1: the mesh arrays were ~13% of the
//! minipbrt set's import CPU).
//!
//! The general reader skips blanks a byte at a time and then parses the number that starts
//! where the skip ended, so each number's start waits on the previous number's parse and on
//! the blank loop's exit branch, which mispredicts wherever runs of blanks vary in length
//! (`0 1 190    0 190 189`). Here the blanks of a 64-byte block are found at once (one bit a
//! byte), every word start in the block is known before any number is parsed, and the
//! parses no longer wait on one another.

use super::{Lexer, CLASS};

/// Bytes a block covers.
const BLOCK: usize = 64;

/// Bytes the fast number parsers may read past a word's start (one 8-byte word), so a block
/// is taken only when this many bytes follow it.
const SLACK: usize = 8;

/// One bit a byte of `block`: the blanks [`Lexer::skip_ws`] skips (space, `\t`, `\n`, `\v`,
/// `\f`, `\r`), and the newlines among them.
#[inline]
fn blank_masks(block: &[u8; BLOCK]) -> (u64, u64) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{
            __m128i, _mm_cmpeq_epi8, _mm_loadu_si128, _mm_min_epu8, _mm_movemask_epi8,
            _mm_or_si128, _mm_set1_epi8, _mm_sub_epi8,
        };
        let mut blank = 0u64;
        let mut newline = 0u64;
        for (i, lane) in block.chunks_exact(16).enumerate() {
            // SAFETY: SSE2 is part of the x86_64 baseline; the unaligned load reads the 16
            // bytes of `lane`, which `chunks_exact` guarantees.
            let (b, n) = unsafe {
                let v = _mm_loadu_si128(lane.as_ptr().cast::<__m128i>());
                let space = _mm_cmpeq_epi8(v, _mm_set1_epi8(b' ' as i8));
                // `\t`..=`\r` are 9..=13: `byte - 9` is at most 4 exactly for them (unsigned).
                let x = _mm_sub_epi8(v, _mm_set1_epi8(9));
                let control = _mm_cmpeq_epi8(_mm_min_epu8(x, _mm_set1_epi8(4)), x);
                let nl = _mm_cmpeq_epi8(v, _mm_set1_epi8(b'\n' as i8));
                (
                    _mm_movemask_epi8(_mm_or_si128(space, control)) as u16,
                    _mm_movemask_epi8(nl) as u16,
                )
            };
            blank |= u64::from(b) << (16 * i);
            newline |= u64::from(n) << (16 * i);
        }
        (blank, newline)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut blank = 0u64;
        let mut newline = 0u64;
        for (i, &b) in block.iter().enumerate() {
            blank |= u64::from(CLASS[b as usize] == 1) << i;
            newline |= u64::from(b == b'\n') << i;
        }
        (blank, newline)
    }
}

impl Lexer<'_> {
    /// Reads numbers into `out` from the current position for as long as every word is a
    /// number followed by a blank, by 64-byte blocks: `fast` (one of the 8-byte parsers) or
    /// else `general` (the general reader's number at a position, `None` on an error) reads
    /// each word. Stops, with everything before it consumed and its lines counted, at the
    /// first word that is not such a number (`]`, a comment, a number followed by `]`, bad
    /// text) or where fewer than 72 bytes remain: the caller's general step reads on from
    /// there, so values, lines, columns and errors are the general reader's.
    #[inline]
    pub(super) fn array_run<T>(
        &mut self,
        out: &mut Vec<T>,
        fast: impl Fn(&[u8], usize) -> Option<(T, usize)>,
        mut general: impl FnMut(&mut Self, usize) -> Option<T>,
    ) {
        let bytes = self.bytes;
        let mut pos = self.pos;
        // Whether a word can start at the block's first byte: at the run's start it does
        // unless that byte is blank; later, when the byte before it is blank.
        let mut carry = 1u64;
        while let Some(window) = bytes.get(pos..pos + BLOCK + SLACK) {
            let Ok(block) = <&[u8; BLOCK]>::try_from(&window[..BLOCK]) else {
                break;
            };
            let (blank, newline) = blank_masks(block);
            let mut starts = !blank & ((blank << 1) | carry);
            // End of the last number read; the byte there is blank.
            let mut end = pos;
            while starts != 0 {
                let at = pos + starts.trailing_zeros() as usize;
                let read = match fast(bytes, at) {
                    Some(read) => Some(read),
                    None => {
                        // The general reader builds its error's location from `pos` (the
                        // error itself is dropped: the caller's general step makes it again).
                        self.pos = at;
                        general(self, at).map(|v| (v, self.pos))
                    }
                };
                match read {
                    Some((v, e)) if bytes.get(e).is_some_and(|&b| CLASS[b as usize] == 1) => {
                        out.push(v);
                        end = e;
                    }
                    _ => {
                        let below = (1u64 << (at - pos)) - 1;
                        self.count_lines(pos, newline & below);
                        self.pos = at;
                        return;
                    }
                }
                starts &= starts - 1;
            }
            self.count_lines(pos, newline);
            carry = blank >> 63;
            pos += BLOCK;
            if end > pos {
                // A number ran past the block (a long one the general reader took).
                pos = end;
                carry = 1;
            }
        }
        self.pos = pos;
    }

    /// Counts the newlines of the block at `base` (bits of `newlines`).
    #[inline]
    fn count_lines(&mut self, base: usize, newlines: u64) {
        if newlines != 0 {
            self.line += newlines.count_ones();
            self.line_start = base + BLOCK - newlines.leading_zeros() as usize;
        }
    }
}

#[cfg(test)]
mod tests;
