//! Crash-safe saves, proven by killing the saver: a child process (this test binary, re-executed
//! in a child mode) saves multi-megabyte maps to one path in a loop, and is killed with SIGKILL
//! at many moments spread over about two save durations, so kills land before the temporary
//! file exists, while it is written, while it is flushed, around the rename and after it.
//! After every kill the test proves that
//!
//! - the file at the path is, byte for byte, one complete save: the previous one or the one in
//!   progress, never a mix, a truncation or an older save (three contents are cycled and the
//!   child reports each finished save, so "previous" and "new" are known exactly), and it
//!   loads with [`Map::load`] and serialises back to the same bytes;
//! - at most one temporary file (`.{name}.topoloc-tmp-XXXXXX`) is left, and it holds a prefix
//!   of the save that was in progress;
//! - the next successful save of the same path removes it: afterwards the directory holds the
//!   map and nothing else, and the new map loads and has exactly the new bytes.
//!
//! The test also counts the kills that left a temporary file behind and fails unless some did,
//! so it cannot pass without having interrupted saves half-way.
//!
//! A save that wrote the target in place (truncate, then write) would fail here: a kill during
//! the write leaves a file shorter than any complete save, which matches none of the known
//! serialisations and fails to load (its length or checksum is wrong).

#![cfg(unix)]

mod common;

use common::{unit_vector, Lcg};
use nalgebra::{Isometry3, Point3, Vector3};
use std::io::{BufRead, BufReader};
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use topoloc::map::{LoadOptions, ViewAttributes};
use topoloc::{DescriptorIdentity, Map, MapBuilder};

/// Set (to the map's path) in the re-executed child: it then saves maps there until killed.
const CHILD_ENV: &str = "TOPOLOC_CRASH_SAVE_CHILD";
/// Index of the content the child saves first (it then cycles through the others).
const FIRST_ENV: &str = "TOPOLOC_CRASH_SAVE_FIRST";
/// This test's name, for re-executing the binary with `--exact`.
const TEST_NAME: &str = "sigkill_mid_save_leaves_a_whole_map_and_no_lasting_temporary";
/// Lines the child writes to stdout: once its maps are built, and after each finished save.
/// (The harness has printed `test NAME ... ` without a newline before the test runs, so the
/// child starts its own line first.)
const READY: &str = "crash-save-child: ready";
const SAVED: &str = "crash-save-child: saved";

/// Different map contents cycled through: three, so that "the previous save or the new one"
/// excludes an older one.
const CONTENTS: usize = 3;
/// Kills. Each costs a process start, about one save and one verification.
const KILLS: usize = 48;
/// Map file name inside the test directory.
const MAP_NAME: &str = "map.topoloc";
/// Descriptor dimension; with about 3000 views a map is about 6 MB.
const DIM: u32 = 512;

/// Content `k`: a chain of about 3000 places, one view each, with poses and keyframe ids;
/// every content has its own descriptors and size. Deterministic, so that the child builds
/// exactly the maps the parent compares with.
fn content_map(k: usize) -> Map {
    let places = 3000 + 7 * k as u32;
    let mut builder = MapBuilder::new(DescriptorIdentity::new("test", "crash-save", DIM).unwrap());
    for p in 0..places {
        let x = 2.0 * f64::from(p);
        let place = builder.add_place(Some(Point3::new(x, 0.0, 0.0))).unwrap();
        let attributes = ViewAttributes {
            keyframe_id: Some(u64::from(p)),
            world_t_camera: Some(Isometry3::new(
                Vector3::new(x, 0.0, 1.5),
                Vector3::z() * 0.1 * f64::from(p % 60),
            )),
            image: None,
        };
        let seed = (k as u64) << 32 | u64::from(p);
        builder
            .add_view(place, &unit_vector(seed, DIM as usize), attributes)
            .unwrap();
        if p > 0 {
            builder.add_edge(p - 1, p, 1.0).unwrap();
        }
    }
    builder.build().unwrap()
}

/// The child: builds the contents, says so, then saves content `first`, `first + 1`, ... (mod
/// [`CONTENTS`]) to `path` forever, reporting each finished save. Never returns.
fn run_child(path: &Path) -> ! {
    use std::io::Write;
    let first: usize = std::env::var(FIRST_ENV).unwrap().parse().unwrap();
    let maps: Vec<Map> = (0..CONTENTS).map(content_map).collect();
    // Unbuffered writes: a line the parent reads is a save that finished, and a save that
    // finished is reported before the next one starts.
    let mut out = std::io::stdout().lock();
    writeln!(out, "\n{READY}").unwrap();
    out.flush().unwrap();
    for k in 0.. {
        maps[(first + k) % CONTENTS].save(path).unwrap();
        writeln!(out, "{SAVED}").unwrap();
        out.flush().unwrap();
    }
    unreachable!("the child saves until it is killed")
}

/// Kills the child when dropped, so that a failing assertion leaves no child saving forever.
struct KillOnDrop(Child);

impl Drop for KillOnDrop {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The names of `dir`'s entries other than the map: temporary files of the map, and anything
/// else (there should be nothing else).
fn leftovers(dir: &Path) -> (Vec<PathBuf>, Vec<PathBuf>) {
    let prefix = format!(".{MAP_NAME}.topoloc-tmp-");
    let mut temporaries = Vec::new();
    let mut others = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let entry = entry.unwrap();
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if name == MAP_NAME {
            continue;
        }
        if name.starts_with(&prefix) {
            temporaries.push(entry.path());
        } else {
            others.push(entry.path());
        }
    }
    (temporaries, others)
}

/// Which of the known serialisations `bytes` is, if any.
fn which(bytes: &[u8], known: &[Vec<u8>]) -> Option<usize> {
    known.iter().position(|k| k.as_slice() == bytes)
}

/// Loads the map at `path` and checks that it serialises back to `bytes`.
fn assert_loads_as(path: &Path, bytes: &[u8], context: &str) {
    let map = Map::load(path, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{context}: the map does not load: {e}"));
    assert!(
        map.to_bytes().unwrap() == bytes,
        "{context}: the loaded map serialises to other bytes"
    );
}

#[test]
fn sigkill_mid_save_leaves_a_whole_map_and_no_lasting_temporary() {
    if let Some(path) = std::env::var_os(CHILD_ENV) {
        run_child(Path::new(&path));
    }
    let started = Instant::now();
    let maps: Vec<Map> = (0..CONTENTS).map(content_map).collect();
    let known: Vec<Vec<u8>> = maps.iter().map(|m| m.to_bytes().unwrap()).collect();
    for i in 0..CONTENTS {
        assert!(known[i].len() > 5 << 20, "a map of several MB");
        assert!(
            maps[i].to_bytes().unwrap() == known[i],
            "serialising is deterministic"
        );
        for j in 0..i {
            assert!(known[i] != known[j], "the contents differ");
        }
    }

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(MAP_NAME);
    // How long a save takes here (the child runs the same code): the median of a few.
    let mut times: Vec<Duration> = (0..5)
        .map(|_| {
            let t = Instant::now();
            maps[0].save(&path).unwrap();
            t.elapsed()
        })
        .collect();
    times.sort();
    let save_time = times[times.len() / 2];
    let mut current = 0; // the content at `path`
    assert!(std::fs::read(&path).unwrap() == known[current]);

    let exe = std::env::current_exe().unwrap();
    let mut rng = Lcg(0x5eed_c0ff_ee00_0016);
    let (mut with_temporary, mut empty_temporary, mut partial_temporary, mut full_temporary) =
        (0, 0, 0, 0);
    let (mut found_previous, mut found_new, mut before_first_save) = (0, 0, 0);
    for kill in 0..KILLS {
        // Delays swept over [0, 2) save durations, jittered within each step.
        let fraction = (kill as f64 + rng.next()) / KILLS as f64;
        let delay = save_time.mul_f64(2.0 * fraction);
        let first = (current + 1) % CONTENTS;
        let mut child = KillOnDrop(
            Command::new(&exe)
                .args([TEST_NAME, "--exact", "--nocapture", "--test-threads=1"])
                .env(CHILD_ENV, &path)
                .env(FIRST_ENV, first.to_string())
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .spawn()
                .unwrap(),
        );
        // The child's lines, read on a thread so that waiting for them can time out; the
        // thread ends when the child's stdout closes (the child is dead).
        let stdout = child.0.stdout.take().unwrap();
        let (send, lines) = mpsc::channel();
        let reader = std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines() {
                if send.send(line.unwrap()).is_err() {
                    break;
                }
            }
        });
        loop {
            match lines.recv_timeout(Duration::from_secs(120)) {
                Ok(line) if line == READY => break,
                Ok(_) => {}
                Err(e) => panic!("kill {kill}: the child never said it was ready ({e})"),
            }
        }
        std::thread::sleep(delay);
        // `Child::kill` sends SIGKILL on Unix (see its documentation): no destructor, no
        // unwinding, no cleanup in the child, exactly like a power cut for the process.
        child.0.kill().unwrap();
        let status = child.0.wait().unwrap();
        assert_eq!(
            status.signal(),
            Some(9),
            "kill {kill}: the child died of SIGKILL, not by itself ({status})"
        );
        reader.join().unwrap();
        // Saves the child finished and reported; one more may have been renamed into place
        // before the report.
        let reported = lines.try_iter().filter(|l| l == SAVED).count();
        let previous = (current + reported) % CONTENTS;
        let new = (previous + 1) % CONTENTS;
        let context = format!(
            "kill {kill} after {delay:?} ({reported} saves reported, content {previous} at the \
             path, content {new} in progress)"
        );

        let bytes = std::fs::read(&path).unwrap();
        match which(&bytes, &known) {
            Some(k) if k == previous => {
                found_previous += 1;
                if reported == 0 {
                    before_first_save += 1;
                }
            }
            Some(k) if k == new => found_new += 1,
            Some(k) => panic!("{context}: the path holds content {k}, an older save"),
            None => panic!(
                "{context}: the path holds {} bytes that are no complete save (torn file)",
                bytes.len()
            ),
        }
        let found = which(&bytes, &known).unwrap();
        assert_loads_as(&path, &bytes, &context);

        let (temporaries, others) = leftovers(dir.path());
        assert!(others.is_empty(), "{context}: unexpected files {others:?}");
        assert!(
            temporaries.len() <= 1,
            "{context}: temporaries of earlier saves survived: {temporaries:?}"
        );
        if let Some(temporary) = temporaries.first() {
            with_temporary += 1;
            assert_eq!(
                found, previous,
                "{context}: a temporary outlived its rename"
            );
            let partial = std::fs::read(temporary).unwrap();
            assert!(
                known[new].starts_with(&partial),
                "{context}: the temporary file holds no prefix of the save in progress"
            );
            match partial.len() {
                0 => empty_temporary += 1,
                n if n < known[new].len() => partial_temporary += 1,
                _ => full_temporary += 1,
            }
        }

        // One more successful save of the same path: the new map is in place, loads, and no
        // temporary file is left.
        let next = (found + 1) % CONTENTS;
        maps[next].save(&path).unwrap();
        let (temporaries, others) = leftovers(dir.path());
        assert!(
            temporaries.is_empty() && others.is_empty(),
            "{context}: the next save left {temporaries:?} {others:?}"
        );
        let bytes = std::fs::read(&path).unwrap();
        assert!(
            bytes == known[next],
            "{context}: the next save wrote other bytes"
        );
        assert_loads_as(&path, &bytes, &format!("{context}, then saved"));
        current = next;
    }

    println!(
        "crash-safe save: {KILLS} SIGKILLs over 0..{:?} (one save of {} bytes: {save_time:?}); \
         {with_temporary} left a temporary file ({empty_temporary} empty, {partial_temporary} \
         partly written, {full_temporary} fully written, not yet renamed), all removed by the \
         next save; the path held the previous save {found_previous} times ({before_first_save} \
         before the child's first save finished) and the new save {found_new} times (renamed, \
         not yet reported), never anything else; {:.1} s",
        save_time * 2,
        known[0].len(),
        started.elapsed().as_secs_f64()
    );
    assert!(
        with_temporary > 0,
        "no kill landed while a temporary file existed: the test did not interrupt a save"
    );
}
