//! Allocator hot path: alloc/free churn with ~50k live allocations (streaming-like load).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use motu_alloc::{AllocKind, AllocLimits, AllocPolicy, AllocRequest, AllocationId, Allocator, GIB};

const OPS: u64 = 20_000;

/// Deterministic churn: keeps between 40k and 60k allocations live, frees at random.
fn churn(allocator: &mut Allocator, live: &mut Vec<AllocationId>, state: &mut u64) {
    for _ in 0..OPS {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let grow = live.len() < 40_000 || (live.len() < 60_000 && *state >> 63 == 0);
        if grow {
            let size_bytes = 1 + (*state >> 20) % (256 * 1024);
            let alignment_bytes = 1 << ((*state >> 10) % 9);
            let request =
                AllocRequest::device_local(AllocKind::Geometry, size_bytes, alignment_bytes);
            if let Ok(allocation) = allocator.alloc(request) {
                live.push(allocation.id);
            }
        } else if !live.is_empty() {
            let index = (*state as usize >> 3) % live.len();
            let _ = allocator.free(live.swap_remove(index));
        }
        allocator.drain_events().for_each(drop);
    }
}

fn alloc_free(c: &mut Criterion) {
    let mut group = c.benchmark_group("allocator");
    group.throughput(Throughput::Elements(OPS));
    group.bench_function("churn_50k_live", |b| {
        b.iter_batched(
            || {
                let mut allocator =
                    Allocator::new(AllocLimits::with_budget(32 * GIB), AllocPolicy::default())
                        .expect("valid limits");
                let mut live = Vec::new();
                let mut state = 1;
                churn(&mut allocator, &mut live, &mut state);
                churn(&mut allocator, &mut live, &mut state);
                churn(&mut allocator, &mut live, &mut state);
                (allocator, live, state)
            },
            |(mut allocator, mut live, mut state)| {
                churn(&mut allocator, &mut live, &mut state);
                allocator
            },
            BatchSize::LargeInput,
        );
    });
    group.finish();
}

criterion_group!(benches, alloc_free);
criterion_main!(benches);
