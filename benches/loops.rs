//! Keyframe database: one loop query (similarity to every keyframe, exclusion, top 5) and one
//! add, at 1,000 and 10,000 keyframes of D = 512.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use topoloc::descriptor::DescriptorIdentity;
use topoloc::loops::{DatabaseOptions, KeyframeDatabase, KeyframeEntry, LoopQuery};
use topoloc_synthetic::random_map;

const DIM: usize = 512;

/// A database of `n` keyframes whose descriptors are the views of a generated map.
fn database(n: usize) -> (KeyframeDatabase, Vec<Vec<f32>>) {
    let map = random_map(n, 4, DIM, 7);
    let identity = DescriptorIdentity::new("bench", "loops", DIM as u32).unwrap();
    let mut db = KeyframeDatabase::new(identity, DatabaseOptions::default()).unwrap();
    let rows: Vec<Vec<f32>> = map.descriptors().chunks(DIM).map(<[f32]>::to_vec).collect();
    for (i, d) in rows.iter().enumerate() {
        db.add(&KeyframeEntry {
            id: i as u64,
            timestamp: i as f64,
            descriptor: d,
            ..Default::default()
        })
        .unwrap();
    }
    eprintln!(
        "{n} keyframes of D = {DIM}: {} bytes per keyframe (KeyframeDatabase::memory_bytes)",
        db.memory_bytes() / n
    );
    (db, rows)
}

fn loop_query(c: &mut Criterion) {
    let mut group = c.benchmark_group("loops");
    for &n in &[1_000usize, 10_000] {
        let (db, rows) = database(n);
        let query = LoopQuery {
            max_results: 5,
            max_id: Some(n as u64 - 50),
            before_timestamp: None,
            min_id_gap: 0,
        };
        let mut i = 0usize;
        group.bench_with_input(BenchmarkId::new("loop_candidates", n), &n, |b, _| {
            b.iter(|| {
                i = (i + 7919) % rows.len();
                db.loop_candidates(&rows[i], &query).unwrap()
            })
        });
        // One candidate per stretch of 10 ids, as the hint detector asks (a sort more).
        let spread = LoopQuery {
            min_id_gap: 10,
            ..query
        };
        group.bench_with_input(BenchmarkId::new("loop_candidates_gap10", n), &n, |b, _| {
            b.iter(|| {
                i = (i + 7919) % rows.len();
                db.loop_candidates(&rows[i], &spread).unwrap()
            })
        });
        let mut grown = db.clone();
        let mut id = n as u64;
        group.bench_with_input(BenchmarkId::new("add", n), &n, |b, _| {
            b.iter(|| {
                id += 1;
                i = (i + 7919) % rows.len();
                grown
                    .add(&KeyframeEntry {
                        id,
                        timestamp: id as f64,
                        descriptor: &rows[i],
                        ..Default::default()
                    })
                    .unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, loop_query);
criterion_main!(benches);
