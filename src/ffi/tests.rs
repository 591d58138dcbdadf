//! The C entry points called directly from Rust: NULL arguments, struct sizes, buffer sizes,
//! panics turned into status codes, and out-parameters left alone on error.

use super::boundary::run;
use super::*;
use std::ffi::{c_char, CStr};
use std::ptr::{null, null_mut};
use topoloc_status::*;

fn last_error() -> String {
    let mut needed = 0usize;
    assert_eq!(
        topoloc_last_error_message(null_mut(), 0, &mut needed),
        TOPOLOC_ERR_BUFFER_TOO_SMALL
    );
    let mut buf = vec![0 as c_char; needed];
    assert_eq!(
        topoloc_last_error_message(buf.as_mut_ptr(), buf.len(), null_mut()),
        TOPOLOC_OK
    );
    unsafe { CStr::from_ptr(buf.as_ptr()) }
        .to_str()
        .unwrap()
        .to_string()
}

/// A 2-place map with 2 views each (D = 4) built through the C builder.
fn small_map() -> *mut topoloc_map {
    let mut builder = null_mut();
    assert_eq!(
        topoloc_map_builder_new(c"test".as_ptr(), null(), 4, &mut builder),
        TOPOLOC_OK
    );
    let mut place = 0;
    let mut view = 0;
    for p in 0..2u32 {
        assert_eq!(
            topoloc_map_builder_add_place(builder, null(), &mut place),
            TOPOLOC_OK
        );
        assert_eq!(place, p);
        for v in 0..2usize {
            let mut d = [0.0f32; 4];
            d[p as usize * 2 + v] = 1.0;
            assert_eq!(
                topoloc_map_builder_add_view(builder, p, d.as_ptr(), 4, null(), &mut view),
                TOPOLOC_OK
            );
        }
    }
    assert_eq!(topoloc_map_builder_add_edge(builder, 0, 1, 1.0), TOPOLOC_OK);
    let mut map = null_mut();
    assert_eq!(topoloc_map_builder_build(builder, &mut map), TOPOLOC_OK);
    topoloc_map_builder_free(builder);
    map
}

/// The small map and a default localizer on it (free both).
fn small_localizer() -> (*mut topoloc_map, *mut topoloc_localizer) {
    let map = small_map();
    let mut localizer = null_mut();
    assert_eq!(
        topoloc_localizer_new(map, null(), &mut localizer),
        TOPOLOC_OK
    );
    (map, localizer)
}

/// A descriptor frame for the small map (D = 4), reading `descriptor`.
fn descriptor_frame(descriptor: &[f32; 4]) -> topoloc_frame {
    topoloc_frame {
        descriptor: descriptor.as_ptr(),
        descriptor_len: 4,
        ..Default::default()
    }
}

/// Processes one descriptor frame of the small map, which must succeed.
fn process_descriptor(
    localizer: *mut topoloc_localizer,
    query: [f32; 4],
    result: *mut topoloc_result,
) {
    let frame = descriptor_frame(&query);
    assert_eq!(
        topoloc_localizer_process(localizer, &frame, result),
        TOPOLOC_OK
    );
}

#[test]
fn panics_become_status_codes_with_a_message() {
    assert_eq!(run(|| panic!("boom {}", 42)), TOPOLOC_ERR_PANIC);
    assert!(last_error().contains("boom 42"), "{}", last_error());
}

#[test]
fn null_arguments_are_refused_and_named() {
    let map = small_map();
    let mut count = 0usize;
    assert_eq!(
        topoloc_map_place_count(null(), &mut count),
        TOPOLOC_ERR_NULL_ARGUMENT
    );
    assert!(last_error().contains("'map'"));
    assert_eq!(
        topoloc_map_place_count(map, null_mut()),
        TOPOLOC_ERR_NULL_ARGUMENT
    );
    assert_eq!(
        topoloc_map_load(null(), null(), null_mut()),
        TOPOLOC_ERR_NULL_ARGUMENT
    );
    assert_eq!(topoloc_map_save(map, null()), TOPOLOC_ERR_NULL_ARGUMENT);
    assert_eq!(
        topoloc_localizer_new(null(), null(), null_mut()),
        TOPOLOC_ERR_NULL_ARGUMENT
    );
    let mut localizer = null_mut();
    assert_eq!(
        topoloc_localizer_new(map, null(), &mut localizer),
        TOPOLOC_OK
    );
    let mut result = topoloc_result::default();
    assert_eq!(
        topoloc_localizer_process(localizer, null(), &mut result),
        TOPOLOC_ERR_NULL_ARGUMENT
    );
    let mut frame = topoloc_frame::default();
    assert_eq!(
        topoloc_localizer_process(localizer, &frame, &mut result),
        TOPOLOC_ERR_DIMENSION_MISMATCH
    );
    frame.descriptor_len = 4;
    assert_eq!(
        topoloc_localizer_process(localizer, &frame, &mut result),
        TOPOLOC_ERR_NULL_ARGUMENT
    );
    assert!(last_error().contains("frame.descriptor"));
    assert_eq!(
        topoloc_localizer_reset(null_mut()),
        TOPOLOC_ERR_NULL_ARGUMENT
    );
    topoloc_localizer_free(localizer);
    topoloc_localizer_free(null_mut());
    topoloc_map_free(map);
    topoloc_map_free(null_mut());
    topoloc_map_builder_free(null_mut());
}

#[test]
fn struct_size_is_checked_and_defaults_fill_it() {
    let map = small_map();
    let mut options = topoloc_localizer_options {
        struct_size: 0,
        temperature: -1.0,
        ..Default::default()
    };
    let size = std::mem::size_of::<topoloc_localizer_options>();
    assert_eq!(
        topoloc_localizer_options_init(&mut options, size),
        TOPOLOC_OK
    );
    assert_eq!((options.struct_size, options.temperature), (size, 0.2));
    assert_eq!(
        topoloc_localizer_options_init(&mut options, 4),
        TOPOLOC_ERR_STRUCT_SIZE
    );
    assert_eq!(
        topoloc_localizer_options_init(null_mut(), size),
        TOPOLOC_ERR_NULL_ARGUMENT
    );
    options.struct_size = 8;
    let mut localizer = null_mut();
    assert_eq!(
        topoloc_localizer_new(map, &options, &mut localizer),
        TOPOLOC_ERR_STRUCT_SIZE
    );
    assert!(localizer.is_null(), "out-parameter written on error");
    assert!(last_error().contains("struct_size"));
    topoloc_map_free(map);
}

#[test]
fn a_struct_size_between_published_layouts_is_refused() {
    // ABI 1.0 frames ended before `image`; a size inside `image` would cut its fields in two.
    let v1_0 = std::mem::offset_of!(topoloc_frame, image);
    let v1_1 = std::mem::size_of::<topoloc_frame>();
    let mut frame = topoloc_frame::default();
    for (size, expected, written) in [
        (v1_0 - 1, TOPOLOC_ERR_STRUCT_SIZE, None),
        (v1_0, TOPOLOC_OK, Some(v1_0)),
        (v1_0 + 8, TOPOLOC_ERR_STRUCT_SIZE, None),
        (v1_1 - 1, TOPOLOC_ERR_STRUCT_SIZE, None),
        (v1_1, TOPOLOC_OK, Some(v1_1)),
        (v1_1 + 64, TOPOLOC_OK, Some(v1_1)), // a newer caller: the known layout is filled
    ] {
        frame.struct_size = 12345;
        // The struct is large enough for every size below v1_1; larger sizes are only written up
        // to v1_1 by the library, which is what this checks.
        assert_eq!(
            topoloc_frame_init(&mut frame, size),
            expected,
            "size {size}"
        );
        let after = written.unwrap_or(12345);
        assert_eq!(frame.struct_size, after, "size {size}");
    }
    // Reading follows the same rule: a cut layout is refused before any field is used.
    let (map, localizer) = small_localizer();
    let mut result = topoloc_result::default();
    let descriptor = [1.0f32, 0.0, 0.0, 0.0];
    let frame = topoloc_frame {
        struct_size: v1_0 + 8,
        ..descriptor_frame(&descriptor)
    };
    assert_eq!(
        topoloc_localizer_process(localizer, &frame, &mut result),
        TOPOLOC_ERR_STRUCT_SIZE
    );
    assert!(
        last_error().contains("not a published layout"),
        "{}",
        last_error()
    );
    let frame = topoloc_frame {
        struct_size: v1_0,
        ..frame
    };
    assert_eq!(
        topoloc_localizer_process(localizer, &frame, &mut result),
        TOPOLOC_OK
    );
    topoloc_localizer_free(localizer);
    topoloc_map_free(map);
}

#[test]
fn process_leaves_result_untouched_on_error_and_fills_candidates() {
    let (map, localizer) = small_localizer();
    let mut candidates = [topoloc_candidate::default(); 1];
    let mut result = topoloc_result {
        candidates: candidates.as_mut_ptr(),
        candidates_capacity: 1,
        ..Default::default()
    };
    result.place = 77;
    let nan = [f32::NAN, 0.0, 0.0, 0.0];
    let frame = descriptor_frame(&nan);
    assert_eq!(
        topoloc_localizer_process(localizer, &frame, &mut result),
        TOPOLOC_ERR_NON_FINITE
    );
    assert_eq!(result.place, 77);
    let query = [0.0f32, 0.0, 0.9, 0.1];
    let frame = descriptor_frame(&query);
    assert_eq!(
        topoloc_localizer_process(localizer, &frame, &mut result),
        TOPOLOC_OK
    );
    assert_eq!(
        (
            result.place,
            result.view,
            result.frame_index,
            result.candidates_len
        ),
        (1, 2, 0, 1)
    );
    assert_eq!(candidates[0].place, 1);
    let bad_pose = [2.0f64; 16];
    let frame = topoloc_frame {
        odometry: bad_pose.as_ptr(),
        timestamp: 1.0,
        ..frame
    };
    assert_eq!(
        topoloc_localizer_process(localizer, &frame, &mut result),
        TOPOLOC_ERR_INVALID_ARGUMENT
    );
    topoloc_localizer_free(localizer);
    topoloc_map_free(map);
}

#[test]
fn a_newer_library_never_writes_past_an_older_callers_struct() {
    // Simulate a caller whose header knew a 1-field-shorter result: the library must write at
    // most `struct_size` bytes and keep the caller's struct_size.
    let (map, localizer) = small_localizer();
    let full = std::mem::size_of::<topoloc_result>();
    let mut storage = vec![0xABu8; full + 16];
    let result = storage.as_mut_ptr().cast::<topoloc_result>();
    assert_eq!(topoloc_result_init(result, full), TOPOLOC_OK);
    process_descriptor(localizer, [1.0, 0.0, 0.0, 0.0], result);
    assert!(
        storage[full..].iter().all(|&b| b == 0xAB),
        "wrote past struct_size"
    );
    assert_eq!(unsafe { (*result).place }, 0);
    topoloc_localizer_free(localizer);
    topoloc_map_free(map);
}

#[test]
fn buffers_report_the_size_needed() {
    let map = small_map();
    let mut needed = 0usize;
    let mut small = [0 as c_char; 2];
    assert_eq!(
        topoloc_map_descriptor_kind(map, small.as_mut_ptr(), 2, &mut needed),
        TOPOLOC_ERR_BUFFER_TOO_SMALL
    );
    assert_eq!(needed, 5);
    let mut neighbours = [0u32; 0];
    let mut count = 0usize;
    assert_eq!(
        topoloc_map_neighbours(map, 0, neighbours.as_mut_ptr(), 0, &mut count),
        TOPOLOC_ERR_BUFFER_TOO_SMALL
    );
    assert_eq!(count, 1);
    assert_eq!(
        topoloc_map_neighbours(map, 9, neighbours.as_mut_ptr(), 0, &mut count),
        TOPOLOC_ERR_UNKNOWN_PLACE
    );
    topoloc_map_free(map);
}

#[test]
fn poses_cross_the_abi_row_major() {
    let mut builder = null_mut();
    assert_eq!(
        topoloc_map_builder_new(c"test".as_ptr(), c"m".as_ptr(), 2, &mut builder),
        TOPOLOC_OK
    );
    let mut place = 0;
    let mut view = 0;
    assert_eq!(
        topoloc_map_builder_add_place(builder, [1.0, 2.0, 3.0].as_ptr(), &mut place),
        TOPOLOC_OK
    );
    // 90 degrees about z, translation (1, 2, 3).
    let pose = [
        0.0, -1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0, 1.0, 3.0, 0.0, 0.0, 0.0, 1.0,
    ];
    let attributes = topoloc_view_attributes {
        world_T_camera: pose.as_ptr(),
        has_keyframe_id: true,
        keyframe_id: 7,
        ..Default::default()
    };
    assert_eq!(
        topoloc_map_builder_add_view(builder, 0, [1.0, 0.0].as_ptr(), 2, &attributes, &mut view),
        TOPOLOC_OK
    );
    let mut map = null_mut();
    assert_eq!(topoloc_map_builder_build(builder, &mut map), TOPOLOC_OK);
    let mut info = topoloc_view_info {
        struct_size: std::mem::size_of::<topoloc_view_info>(),
        place: 0,
        has_keyframe_id: false,
        keyframe_id: 0,
        has_pose: false,
        world_T_camera: [0.0; 16],
    };
    assert_eq!(topoloc_map_view_info(map, 0, &mut info), TOPOLOC_OK);
    assert!(info.has_pose && info.has_keyframe_id && info.keyframe_id == 7);
    for (got, want) in info.world_T_camera.iter().zip(pose) {
        assert!((got - want).abs() < 1e-12, "{:?}", info.world_T_camera);
    }
    let skewed = [
        1.0, 0.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
    ];
    let attributes = topoloc_view_attributes {
        world_T_camera: skewed.as_ptr(),
        ..Default::default()
    };
    assert_eq!(
        topoloc_map_builder_add_view(builder, 0, [0.0, 1.0].as_ptr(), 2, &attributes, &mut view),
        TOPOLOC_ERR_INVALID_ARGUMENT
    );
    topoloc_map_builder_free(builder);
    topoloc_map_free(map);
}

#[test]
fn status_strings_and_versions() {
    let text = |code| {
        unsafe { CStr::from_ptr(topoloc_status_str(code)) }
            .to_str()
            .unwrap()
    };
    assert_eq!(text(0), "ok");
    assert_eq!(text(TOPOLOC_ERR_CORRUPT as u32), "corrupt map file");
    assert_eq!(text(12345), "unknown status code");
    assert_eq!(
        unsafe { CStr::from_ptr(topoloc_version()) }
            .to_str()
            .unwrap(),
        env!("CARGO_PKG_VERSION")
    );
    assert_eq!(topoloc_abi_version(), TOPOLOC_ABI_VERSION);
}

#[test]
fn the_status_table_matches_the_header_and_names_every_code() {
    let header = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/include/topoloc.h"))
        .expect("include/topoloc.h");
    let mut in_header = Vec::new();
    for line in header.lines() {
        let line = line.trim().trim_end_matches(',');
        if let Some((name, value)) = line.split_once(" = ") {
            if name.starts_with("TOPOLOC_OK") || name.starts_with("TOPOLOC_ERR_") {
                in_header.push((
                    name.to_string(),
                    value.parse::<u32>().expect("numeric code"),
                ));
            }
        }
    }
    let table: Vec<(String, u32)> = topoloc_status::all()
        .map(|s| {
            let name = unsafe { CStr::from_ptr(topoloc_status_name(s as u32)) };
            (name.to_str().unwrap().to_string(), s as u32)
        })
        .collect();
    assert_eq!(table, in_header, "status table and header disagree");
    assert!(
        table.windows(2).all(|w| w[0].1 < w[1].1),
        "codes unique, ascending"
    );
    for status in topoloc_status::all() {
        let (name, text) = status.entry();
        assert!(
            !text.is_empty() && text != c"unknown status code",
            "{name:?}"
        );
        assert_eq!(topoloc_status::from_code(status as u32), Some(status));
        assert_eq!(
            unsafe { CStr::from_ptr(topoloc_status_str(status as u32)) },
            text
        );
    }
    assert!(topoloc_status_name(7).is_null());
    assert!(topoloc_status_name(u32::MAX).is_null());
    assert_eq!(topoloc_abi_version_minor(), TOPOLOC_ABI_VERSION_MINOR);
    assert!(header.contains(&format!(
        "#define TOPOLOC_ABI_VERSION_MINOR {TOPOLOC_ABI_VERSION_MINOR}"
    )));
}

#[test]
fn a_result_of_the_oldest_layout_is_read_and_written_within_its_size() {
    let (map, localizer) = small_localizer();
    let oldest = <topoloc_result as super::versioned::Versioned>::LAYOUTS[0];
    assert!(oldest < std::mem::size_of::<topoloc_result>());
    // Guard bytes right after the caller's struct: nothing may change them.
    let mut storage = vec![0xCDu8; oldest + 64];
    let result = storage.as_mut_ptr().cast::<topoloc_result>();
    assert_eq!(topoloc_result_init(result, oldest), TOPOLOC_OK);
    let mut candidates = [topoloc_candidate::default(); 2];
    unsafe {
        (*result).candidates = candidates.as_mut_ptr();
        (*result).candidates_capacity = 2;
    }
    process_descriptor(localizer, [0.0, 0.0, 1.0, 0.0], result);
    assert!(
        storage[oldest..].iter().all(|&b| b == 0xCD),
        "wrote past struct_size"
    );
    let struct_size = unsafe { result.cast::<usize>().read_unaligned() };
    assert_eq!(struct_size, oldest);
    assert_eq!(candidates[0].place, 1);
    topoloc_localizer_free(localizer);
    topoloc_map_free(map);
}

/// The "Errors:" lists of the header's function docs, as `(text of the list, the function)`.
fn errors_lists(header: &str) -> Vec<(String, String)> {
    let mut lists = Vec::new();
    for doc_and_decl in header.split("/**").skip(1) {
        let Some((doc, decl)) = doc_and_decl.split_once("*/") else {
            continue;
        };
        let Some(list) = doc.split("Errors:").nth(1) else {
            continue;
        };
        let function = decl
            .split('(')
            .next()
            .unwrap_or("")
            .split_whitespace()
            .last();
        let text: String = list.split_whitespace().collect::<Vec<_>>().join(" ");
        lists.push((text, function.unwrap_or("").to_string()));
    }
    lists
}

#[test]
fn errors_lists_name_only_what_the_general_rules_do_not_cover() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/include/topoloc.h");
    let header = std::fs::read_to_string(path).unwrap();
    assert!(header.contains("A function's \"Errors:\" list names what is specific to it"));
    let lists = errors_lists(&header);
    assert!(lists.len() >= 25, "too few Errors: lists: {}", lists.len());
    let general = [
        "_NULL_ARGUMENT`",
        "_STRUCT_SIZE`",
        "_INVALID_UTF8`",
        "_PANIC`",
        "_CONCURRENT_USE`",
    ];
    let mut restated = Vec::new();
    for (list, function) in &lists {
        for code in general {
            // Named without a reason of its own: the general rule already says it.
            for (at, _) in list.match_indices(code) {
                let after = list[at + code.len()..].trim_start();
                if !after.starts_with('(') {
                    restated.push(format!("{function}: {code}"));
                }
            }
        }
    }
    assert!(
        restated.is_empty(),
        "general errors restated: {restated:#?}"
    );
}
