//! Sample blocks: the ranges of sample indices, doubling in length, that an integrator learning
//! from the film's own paths prepares for one after another, so that what a sample sees depends
//! on its index alone, never on how a render's samples are split into passes.

use std::ops::Range;

/// The first sample of block `block` (see [`block_of`]).
pub fn block_start(block_spp: u32, block: u32) -> u64 {
    let blocks_before = 1u64.checked_shl(block).map_or(u64::MAX, |b| b - 1);
    (block_spp as u64).saturating_mul(blocks_before)
}

/// The block of sample `sample`: block `b` holds samples `block_spp · (2^b − 1)` up to
/// `block_spp · (2^(b+1) − 1)`.
pub fn block_of(block_spp: u32, sample: u64) -> u32 {
    (sample / block_spp as u64 + 1).ilog2()
}

/// The blocks that samples `samples` fall in (the first block's alone when it is empty).
pub fn blocks_of(block_spp: u32, samples: Range<u64>) -> Range<u32> {
    let last = samples.end.saturating_sub(1).max(samples.start);
    block_of(block_spp, samples.start)..block_of(block_spp, last) + 1
}

/// `samples` cut at the starts of sample blocks.
pub fn block_segments(block_spp: u32, samples: Range<u64>) -> Vec<Range<u64>> {
    let mut segments = Vec::new();
    let mut start = samples.start;
    while start < samples.end {
        let next = block_start(block_spp, block_of(block_spp, start) + 1).min(samples.end);
        segments.push(start..next);
        start = next;
    }
    segments
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_blocks_double_in_length() {
        // block_spp 4: samples 0..4, 4..12, 12..28, 28..60, …
        let blocks: Vec<u32> = (0..61).map(|s| block_of(4, s)).collect();
        for (s, &b) in blocks.iter().enumerate() {
            let start = 4 * ((1u64 << b) - 1);
            let end = 4 * ((1u64 << (b + 1)) - 1);
            assert!(
                (start..end).contains(&(s as u64)),
                "sample {s} in block {b}"
            );
        }
        assert_eq!(block_of(1, 0), 0);
        assert_eq!(block_of(1, u64::MAX - 1), 63);
    }

    #[test]
    fn sample_ranges_name_the_blocks_they_fall_in() {
        assert_eq!(blocks_of(4, 0..4), 0..1);
        assert_eq!(blocks_of(4, 0..5), 0..2);
        assert_eq!(blocks_of(4, 11..13), 1..3);
        assert_eq!(blocks_of(4, 7..7), 1..2);
    }

    #[test]
    fn renders_are_segmented_at_block_starts() {
        assert_eq!(block_segments(4, 0..30), vec![0..4, 4..12, 12..28, 28..30]);
        assert_eq!(block_segments(4, 5..11), vec![5..11]);
        assert_eq!(block_segments(4, 11..13), vec![11..12, 12..13]);
        assert_eq!(block_segments(4, 7..7), Vec::<Range<u64>>::new());
        // The last block ends where the sample indices do.
        assert_eq!(
            block_segments(1, u64::MAX - 3..u64::MAX - 1),
            vec![u64::MAX - 3..u64::MAX - 1]
        );
    }
}
