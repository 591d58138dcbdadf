//! Support for topoloc's libFuzzer harnesses (fuzz/harness/*.c), which call the C ABI.
//!
//! A map file is checksummed, so byte-level mutation alone mostly exercises the checksum
//! test. [`topoloc_fuzz_mutate_map`] mutates a file's structure (the metadata JSON, the tensor
//! table, a tensor's bytes or length) and then recomputes its checksum with
//! [`topoloc::map::reseal`], so that the inputs reach every check after it.
//! [`topoloc_fuzz_splice_describer`] puts a fuzzed describer spec into a base map.

use serde_json::{Map as JsonMap, Value};

extern "C" {
    /// libFuzzer's own byte mutator (provided by `-fsanitize=fuzzer`).
    fn LLVMFuzzerMutate(data: *mut u8, size: usize, max_size: usize) -> usize;
}

/// A small deterministic generator (xorshift64*) seeded by libFuzzer.
struct Rng(u64);

impl Rng {
    fn new(seed: u32) -> Self {
        Rng(u64::from(seed).wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (self.next() % n as u64) as usize
        }
    }
}

/// A safetensors file split into its metadata object, its tensor table and its data.
struct Container {
    metadata: Value,
    table: JsonMap<String, Value>,
    data: Vec<u8>,
}

impl Container {
    fn split(bytes: &[u8]) -> Option<Container> {
        let n = usize::try_from(u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?)).ok()?;
        let header = bytes.get(8..8usize.checked_add(n)?)?;
        let mut table: JsonMap<String, Value> = serde_json::from_slice(header).ok()?;
        let metadata = table.remove("__metadata__")?;
        Some(Container {
            metadata,
            table,
            data: bytes[8 + n..].to_vec(),
        })
    }

    fn join(&self) -> Vec<u8> {
        let mut header = format!("{{\"__metadata__\":{}", self.metadata);
        for (name, entry) in &self.table {
            header.push_str(&format!(",{}:{entry}", Value::String(name.clone())));
        }
        header.push('}');
        while header.len() % 8 != 0 {
            header.push(' ');
        }
        let mut out = Vec::with_capacity(8 + header.len() + self.data.len());
        out.extend_from_slice(&(header.len() as u64).to_le_bytes());
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(&self.data);
        out
    }

    /// The `topoloc` metadata object, parsed.
    fn topoloc(&self) -> Option<Value> {
        serde_json::from_str(self.metadata.get("topoloc")?.as_str()?).ok()
    }

    fn set_topoloc(&mut self, value: &Value) {
        if let Some(m) = self.metadata.as_object_mut() {
            m.insert("topoloc".into(), Value::String(value.to_string()));
        }
    }

    /// A tensor's byte range in `data`, when its offsets are sane.
    fn range(&self, name: &str) -> Option<std::ops::Range<usize>> {
        let offsets = self.table.get(name)?.get("data_offsets")?;
        let start = usize::try_from(offsets.get(0)?.as_u64()?).ok()?;
        let end = usize::try_from(offsets.get(1)?.as_u64()?).ok()?;
        (start <= end && end <= self.data.len()).then_some(start..end)
    }

    /// Replaces a tensor's bytes (another length), moving the tensors after it.
    fn resize_tensor(&mut self, name: &str, bytes: Vec<u8>) -> Option<()> {
        let old = self.range(name)?;
        let delta = bytes.len() as i64 - old.len() as i64;
        self.data.splice(old.clone(), bytes);
        let (start, end) = (old.start as u64, old.end as u64);
        for (_, entry) in self.table.iter_mut() {
            let offsets = entry.get_mut("data_offsets")?.as_array_mut()?;
            for o in offsets.iter_mut() {
                let v = o.as_u64()?;
                if v >= end && (v > start || start == end) {
                    *o = Value::from((v as i64 + delta).max(0) as u64);
                }
            }
        }
        let new_end = (old.end as i64 + delta) as u64;
        let offsets = self.table.get_mut(name)?.get_mut("data_offsets")?;
        *offsets = Value::from(vec![old.start as u64, new_end]);
        Some(())
    }
}

/// Values that probe bounds: zero, signs, powers of two around integer widths, huge floats.
fn interesting_number(rng: &mut Rng) -> Value {
    const INTEGERS: [i64; 12] = [
        0,
        1,
        -1,
        2,
        7,
        255,
        65_536,
        65_537,
        i32::MAX as i64,
        u32::MAX as i64,
        u32::MAX as i64 + 1,
        1 << 53,
    ];
    match rng.below(4) {
        0 => Value::from(u64::MAX),
        1 => serde_json::Number::from_f64([1e308, -1e308, 0.5, -0.0, 1e-45][rng.below(5)])
            .map(Value::Number)
            .unwrap_or(Value::Null),
        _ => Value::from(INTEGERS[rng.below(INTEGERS.len())]),
    }
}

/// Every path (object keys and array indices) to a value inside `v`.
fn paths(v: &Value, prefix: &mut Vec<Value>, out: &mut Vec<Vec<Value>>) {
    out.push(prefix.clone());
    match v {
        Value::Object(m) => {
            for (k, child) in m {
                prefix.push(Value::String(k.clone()));
                paths(child, prefix, out);
                prefix.pop();
            }
        }
        Value::Array(a) => {
            for (i, child) in a.iter().enumerate().take(64) {
                prefix.push(Value::from(i));
                paths(child, prefix, out);
                prefix.pop();
            }
        }
        _ => {}
    }
}

fn at_path<'a>(v: &'a mut Value, path: &[Value]) -> Option<&'a mut Value> {
    path.iter().try_fold(v, |v, step| match step {
        Value::String(k) => v.get_mut(k.as_str()),
        Value::Number(i) => v.get_mut(i.as_u64()? as usize),
        _ => None,
    })
}

/// Runs libFuzzer's byte mutator on a copy of `bytes` with room to grow by `extra`.
fn byte_mutate(bytes: &[u8], extra: usize) -> Vec<u8> {
    let mut buf = bytes.to_vec();
    let size = buf.len();
    buf.resize(size + extra, 0);
    if size == 0 {
        buf[0] = b'0';
    }
    // SAFETY: the buffer holds `size + extra` bytes, of which the first `max(size, 1)` are set.
    let new = unsafe { LLVMFuzzerMutate(buf.as_mut_ptr(), size.max(1), buf.len()) };
    buf.truncate(new);
    buf
}

/// One structural edit of a JSON document: a value replaced by a probing one, a key removed,
/// an array element repeated, or a scalar's text mutated byte-wise.
fn mutate_json(value: &mut Value, rng: &mut Rng) {
    let mut all = Vec::new();
    paths(value, &mut Vec::new(), &mut all);
    let path = all[rng.below(all.len())].clone();
    match rng.below(5) {
        0 | 1 => {
            if let Some(v) = at_path(value, &path) {
                *v = interesting_number(rng);
            }
        }
        2 => {
            let Some((last, parent)) = path.split_last() else {
                return;
            };
            if let (Some(Value::Object(m)), Value::String(k)) = (at_path(value, parent), last) {
                m.remove(k);
            }
        }
        3 => {
            if let Some(Value::Array(a)) = at_path(value, &path) {
                if let Some(first) = a.first().cloned() {
                    let times = 1 + rng.below(3);
                    a.extend(std::iter::repeat_n(first, times));
                } else {
                    a.push(interesting_number(rng));
                }
            }
        }
        _ => {
            if let Some(v) = at_path(value, &path) {
                let text = match &*v {
                    Value::String(s) => s.clone(),
                    other => other.to_string(),
                };
                let mutated =
                    String::from_utf8_lossy(&byte_mutate(text.as_bytes(), 16)).into_owned();
                *v = serde_json::from_str::<Value>(&mutated)
                    .ok()
                    .filter(|n| n.is_number())
                    .unwrap_or(Value::String(mutated));
            }
        }
    }
}

/// One structure-aware mutation of a map file, resealed; `None` when the input is not a
/// container this mutator understands (the caller falls back to byte mutation).
fn mutate_map(bytes: &[u8], rng: &mut Rng) -> Option<Vec<u8>> {
    let mut c = Container::split(bytes)?;
    let names: Vec<String> = c.table.keys().cloned().collect();
    match rng.below(10) {
        // The metadata: counts, identity, version, describer spec.
        0..=3 => {
            let mut meta = c.topoloc()?;
            for _ in 0..1 + rng.below(2) {
                mutate_json(&mut meta, rng);
            }
            c.set_topoloc(&meta);
        }
        // The tensor table: dtypes, shapes, offsets.
        4 | 5 => {
            let name = names.get(rng.below(names.len()))?;
            let entry = c.table.get_mut(name)?;
            if rng.below(3) == 0 {
                let dtypes = ["F32", "F64", "U8", "I8", "U32", "U64", "F16", "BOOL"];
                entry["dtype"] = Value::from(dtypes[rng.below(dtypes.len())]);
            } else {
                mutate_json(entry, rng);
            }
        }
        // A tensor's bytes, same length.
        6 | 7 => {
            let name = names.get(rng.below(names.len()))?;
            let range = c.range(name)?;
            if range.is_empty() {
                return None;
            }
            let mutated = byte_mutate(&c.data[range.clone()], 0);
            let n = mutated.len().min(range.len());
            c.data[range.start..range.start + n].copy_from_slice(&mutated[..n]);
        }
        // A tensor's length (and, half the time, its shape to match): more or fewer rows.
        _ => {
            let name = names.get(rng.below(names.len()))?.clone();
            let range = c.range(&name)?;
            let old = c.data[range.clone()].to_vec();
            let new_len = match rng.below(4) {
                0 => 0,
                1 => old.len() / 2,
                _ => old.len() + 8 * (1 + rng.below(64)),
            };
            let mut bytes: Vec<u8> = old.iter().copied().cycle().take(new_len).collect();
            bytes.resize(new_len, 0);
            c.resize_tensor(&name, bytes)?;
            if rng.below(2) == 0 {
                let shape = c.table.get_mut(&name)?.get_mut("shape")?.as_array_mut()?;
                if let Some(first) = shape.first_mut() {
                    let row: u64 = shape_row_bytes(first, old.len());
                    *first = Value::from(new_len as u64 / row.max(1));
                }
            }
        }
    }
    let joined = c.join();
    Some(topoloc::map::reseal(&joined).unwrap_or(joined))
}

/// Bytes per first-axis row of a tensor of `total` bytes whose first extent is `first`.
fn shape_row_bytes(first: &Value, total: usize) -> u64 {
    match first.as_u64() {
        Some(rows) if rows > 0 => total as u64 / rows,
        _ => 1,
    }
}

/// libFuzzer custom mutator for map files (called from the harness's
/// `LLVMFuzzerCustomMutator`): mostly structure-aware and resealed, one time in eight plain
/// byte mutation of the whole file. Returns the new size (at most `max_size`).
///
/// # Safety
/// `data` must hold `max_size` writable bytes, the first `size` of them initialised.
#[no_mangle]
pub unsafe extern "C" fn topoloc_fuzz_mutate_map(
    data: *mut u8,
    size: usize,
    max_size: usize,
    seed: u32,
) -> usize {
    let mut rng = Rng::new(seed);
    let input = std::slice::from_raw_parts(data, size);
    let mutated = if rng.below(8) == 0 {
        None
    } else {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| mutate_map(input, &mut rng)))
            .ok()
            .flatten()
    };
    match mutated {
        Some(bytes) if bytes.len() <= max_size => {
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), data, bytes.len());
            bytes.len()
        }
        _ => LLVMFuzzerMutate(data, size, max_size),
    }
}

/// A copy of the map file `base` whose describer spec is the JSON text `spec` (resealed), in
/// a buffer to release with [`topoloc_fuzz_free`]; NULL when `base` is not a map or `spec` is
/// not JSON. `*out_len` receives the length.
///
/// # Safety
/// `base` and `spec` must point to `base_len` and `spec_len` readable bytes, `out_len` to a
/// writable `usize`.
#[no_mangle]
pub unsafe extern "C" fn topoloc_fuzz_splice_describer(
    base: *const u8,
    base_len: usize,
    spec: *const u8,
    spec_len: usize,
    out_len: *mut usize,
) -> *mut u8 {
    let base = std::slice::from_raw_parts(base, base_len);
    let spec = std::slice::from_raw_parts(spec, spec_len);
    let spliced = (|| {
        let spec: Value = serde_json::from_slice(spec).ok()?;
        let mut c = Container::split(base)?;
        let mut meta = c.topoloc()?;
        meta.as_object_mut()?.insert("describer".into(), spec);
        c.set_topoloc(&meta);
        let joined = c.join();
        topoloc::map::reseal(&joined)
    })();
    match spliced {
        Some(bytes) => {
            *out_len = bytes.len();
            Box::into_raw(bytes.into_boxed_slice()) as *mut u8
        }
        None => std::ptr::null_mut(),
    }
}

/// Releases a buffer of [`topoloc_fuzz_splice_describer`]; NULL is a no-op.
///
/// # Safety
/// `ptr` and `len` must come from one call of [`topoloc_fuzz_splice_describer`].
#[no_mangle]
pub unsafe extern "C" fn topoloc_fuzz_free(ptr: *mut u8, len: usize) {
    if !ptr.is_null() {
        drop(Box::from_raw(std::ptr::slice_from_raw_parts_mut(ptr, len)));
    }
}
