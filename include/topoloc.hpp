/*
 * topoloc.hpp: header-only C++17 RAII layer over the C ABI in topoloc.h.
 *
 * Every owner class (`Map`, `MapBuilder`, `Localizer`, `Graph`, `Describer`,
 * `KeyframeDescriber`, `LoopDetector`) is the one move-only owner template `detail::Owner` over
 * one C handle: its destructor calls the matching C `_free` function, `capi()` / `get()` return
 * the raw handle for code that talks to the C API directly, and `release()` gives it up. Every
 * failing C call is turned into a `topoloc::Error` exception (or a subclass) carrying the C
 * status and the thread-local message of `topoloc_last_error_message`; `throw_error` maps each
 * status to its exception class in one switch. Nothing here adds behaviour the C API does not
 * have; the C header documents the semantics of each call, and each option's meaning, default
 * and range.
 *
 * This header includes the whole layer, one concept per file in topoloc/ (each may also be
 * included alone, e.g. `#include <topoloc/map.hpp>`):
 *
 *   topoloc/error.hpp       statuses, `Error` and its subclasses, `check`
 *   topoloc/version.hpp     `version`, `abi_version`, `abi_matches`
 *   topoloc/logging.hpp     `set_log_handler`, `LogLevel`
 *   topoloc/geometry.hpp    `Position`, `Pose`
 *   topoloc/image.hpp       `Image`, `image_view`, `DepthImage`, `depth_view`
 *   topoloc/progress.hpp    `Progress`, `Stage` (callbacks of map builds)
 *   topoloc/options.hpp     every operation's options (`LoadOptions`, `LocalizerOptions`, ...)
 *                           and their `default_*_options()`; `LocalFeatures`
 *   topoloc/map.hpp         `Map`, `MapBuilder`, `map_from_keyframes`
 *   topoloc/graph.hpp       `Graph` (skeleton graph of an occupancy grid)
 *   topoloc/localizer.hpp   `Localizer`, `Frame`, `Result`
 *   topoloc/describer.hpp   `Describer`
 *   topoloc/keyframes.hpp   `KeyframeDescriber` (keyframe images for a loop detector)
 *   topoloc/loops.hpp       `LoopDetector`, `LoopKeyframe`, `LoopHint`, `Gate`, `Translation`,
 *                           `LoopCandidateCheck`
 *   topoloc/trajectory.hpp  `evaluate_trajectory`, `evaluate_trajectory_files`
 *   topoloc/detail.hpp      internal: `detail::Owner`, filled C structs, string and array reads
 *
 * One name per operation. The per-frame call is `process` in C, C++ and Python; the Rust core
 * calls it `Localizer::localize(&Frame) -> Localization`.
 *
 *   operation                 C                                   C++                                Python
 *   load a map file           topoloc_map_load                    Map::load                          Map.load
 *   load a map from bytes     topoloc_map_load_from_memory        Map::from_memory                   Map.from_bytes
 *   save a map                topoloc_map_save                    Map::save                          Map.save
 *   build from descriptors    topoloc_map_builder_new/_add_*      MapBuilder, add_place/view/edge    MapBuilder
 *                             topoloc_map_builder_build           MapBuilder::build                  MapBuilder.build
 *   build from keyframes      topoloc_map_from_keyframes          map_from_keyframes                 map_from_keyframes
 *   build from images         topoloc_map_build_from_images       Map::build_from_images             Map.build_from_images
 *   build from image files    topoloc_map_build_from_image_files  Map::build_from_image_files        Map.build_from_image_files
 *   attach scene points       topoloc_map_with_keypoint_points    Map::with_keypoint_points          Map.with_keypoint_points
 *   graph from occupancy      topoloc_graph_from_occupancy        Graph::from_occupancy              skeleton_graph
 *   new localizer             topoloc_localizer_new               Localizer(map, options)            Localizer(map, ...)
 *   one frame (descriptor     topoloc_localizer_process           Localizer::process                 Localizer.process
 *     or image)                                                   (+ process_descriptor,
 *                                                                 process_image of a cv::Mat in
 *                                                                 topoloc_opencv.hpp)
 *   forget history            topoloc_localizer_reset             Localizer::reset                   Localizer.reset
 *   new loop detector         topoloc_loop_detector_new           LoopDetector::create               LoopDetector(kind, ...)
 *     for a map's descriptors                                     LoopDetector::for_descriptors_of   LoopDetector.for_descriptors_of
 *   loop detector from a map  topoloc_loop_detector_from_map      LoopDetector::from_map             LoopDetector.from_map
 *   add a keyframe (a hint)   topoloc_loop_detector_add           LoopDetector::add                  LoopDetector.add
 *   describe keyframe images  topoloc_keyframe_describer_new      KeyframeDescriber(map, options)    KeyframeDescriber(map, ...)
 *   add a keyframe image      topoloc_loop_detector_add_image     LoopDetector::add_image            LoopDetector.add_image
 *   its verified candidates   topoloc_loop_detector_candidates    LoopDetector::candidates           LoopDetector.candidates
 *   new session (new world)   topoloc_loop_detector_begin_session LoopDetector::begin_session        LoopDetector.begin_session
 *   hints it confirmed        topoloc_loop_detector_confirmed     LoopDetector::confirmed            LoopDetector.confirmed
 *                             (+ _confirmed_count)
 *   relocalization            topoloc_loop_detector_query         LoopDetector::query                LoopDetector.query
 *   cull a keyframe           topoloc_loop_detector_erase         LoopDetector::erase                LoopDetector.erase
 *   save the session          topoloc_loop_detector_save          LoopDetector::save                 LoopDetector.save
 *   keyframes held            topoloc_loop_detector_len           LoopDetector::size                 len(LoopDetector)
 *   the next keyframe's id    topoloc_loop_detector_next_id       LoopDetector::next_id              LoopDetector.next_id
 *   trajectory ATE/RPE        topoloc_trajectory_evaluate         evaluate_trajectory                evaluate_trajectory
 *                             topoloc_trajectory_evaluate_files   evaluate_trajectory_files          evaluate_trajectory_files
 *
 * Thread safety (the C rules, restated):
 *  - `Map`, `Graph`: immutable. A const one may be shared by many threads, its const methods
 *    called concurrently; many localizers on many threads may use one map.
 *  - `MapBuilder`, `Localizer`, `Describer`, `KeyframeDescriber`, `LoopDetector`:
 *    single-threaded state. Use each from one thread at a time (they may move between threads).
 *  - Error messages are per thread, so an `Error` always describes the failure of the call that
 *    threw it on that thread.
 *
 * Moved-from and default-constructed owners are empty (`!owner`, `capi() == nullptr`); calling a
 * method on an empty owner throws `Error` with `TOPOLOC_ERR_NULL_ARGUMENT`.
 *
 * Callbacks (the progress of map builds) are called from inside topoloc: they must not unwind,
 * longjmp or otherwise jump through it. This layer wraps a C++ callback so that an exception it
 * throws is caught before it reaches C, cancels the build, and is rethrown after the C call
 * returns; code that gives topoloc a C callback itself must do the same.
 *
 * Methods returning strings or id lists ask the library for the size first; such a sizing call
 * may leave a "buffer too small" text as the thread's `topoloc_last_error_message` even though
 * the method succeeds. Errors thrown by this layer always carry the right message.
 *
 * Images: `Image` is a borrowed view of pixels (the C `topoloc_image`; make one with
 * `image_view`). `Map::build_from_images` / `Map::build_from_image_files` build maps that store
 * their describer, with an optional progress callback; `Localizer::process` takes image frames
 * as well as descriptors. The image statuses throw subclasses of `Error` (`InvalidImageError`,
 * `UninformativeImageError`, `BackendUnavailableError`, `ModelError`, `NoDescriberError`,
 * `CancelledError`), so a stream can skip frames with
 * `catch (const topoloc::UninformativeImageError &)`.
 *
 * OpenCV: `cv::Mat` conveniences live in topoloc_opencv.hpp (which includes this header and
 * OpenCV). Nothing in this header or in topoloc/ depends on what was included before it.
 */

#ifndef TOPOLOC_HPP
#define TOPOLOC_HPP

#include "topoloc.h"

#include "topoloc/error.hpp"
#include "topoloc/version.hpp"
#include "topoloc/logging.hpp"
#include "topoloc/detail.hpp"
#include "topoloc/geometry.hpp"
#include "topoloc/image.hpp"
#include "topoloc/progress.hpp"
#include "topoloc/options.hpp"
#include "topoloc/map.hpp"
#include "topoloc/graph.hpp"
#include "topoloc/localizer.hpp"
#include "topoloc/describer.hpp"
#include "topoloc/keyframes.hpp"
#include "topoloc/loops.hpp"
#include "topoloc/trajectory.hpp"

#endif // TOPOLOC_HPP
