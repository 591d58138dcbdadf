//! Deterministic grey test images: a "place" of random rectangles and the same place seen again.

use topoloc::image::{ImageView, PixelFormat};

/// Test image width.
pub const W: usize = 320;
/// Test image height.
pub const H: usize = 240;

/// A deterministic "place": overlapping rectangles and bars of pseudo-random grey shades.
pub fn place_image(seed: u64) -> Vec<u8> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(7);
    let mut next = move |m: usize| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 33) as usize % m
    };
    let mut data = vec![0u8; W * H];
    for (i, px) in data.iter_mut().enumerate() {
        *px = ((i % W) * 255 / W) as u8 / 2 + 40;
    }
    for _ in 0..150 {
        let (x0, y0, w, h) = (next(W), next(H), 6 + next(50), 6 + next(50));
        let shade = next(256) as u8;
        for y in y0..(y0 + h).min(H) {
            for x in x0..(x0 + w).min(W) {
                data[y * W + x] = shade;
            }
        }
    }
    data
}

/// The same place seen again: brighter, shifted by a few pixels, with noise.
pub fn revisit(image: &[u8], seed: u64) -> Vec<u8> {
    let mut state = seed;
    let mut out = vec![0u8; W * H];
    for y in 0..H {
        for x in 0..W {
            let src = image[y * W + (x + 3).min(W - 1)];
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let noise = ((state >> 60) as i32) - 8;
            out[y * W + x] = (i32::from(src) * 11 / 10 + 10 + noise).clamp(0, 255) as u8;
        }
    }
    out
}

pub fn gray(data: &[u8]) -> ImageView<'_> {
    ImageView::packed(W as u32, H as u32, PixelFormat::Gray8, data)
}

/// A map of `images` (one place each) built with the VLAD backend on two threads: describer
/// (PCA, codebook) and keypoints included.
pub fn vlad_image_map(images: &[Vec<u8>]) -> topoloc::Map {
    vlad_image_map_with(images, Default::default())
}

/// As [`vlad_image_map`], with the PCA rows stored at `precision`.
pub fn vlad_image_map_with(
    images: &[Vec<u8>],
    precision: topoloc::describe::PcaPrecision,
) -> topoloc::Map {
    use topoloc::build::{build_from_images, ImageLayout, ImageMapOptions, ImageSource};
    use topoloc::describe::{vlad::VladOptions, BackendConfig, FitOptions};
    let sources: Vec<ImageSource> = images
        .iter()
        .map(|d| ImageSource::Pixels(gray(d)))
        .collect();
    let options = ImageMapOptions {
        backend: BackendConfig::Vlad(VladOptions::default()),
        fit: FitOptions {
            pca_precision: precision,
            ..FitOptions::default()
        },
        threads: 2,
        // No learned weights at all: ORB keypoints (the default, XFeat, needs its network).
        features: topoloc::verify::FeatureKind::Orb,
        ..ImageMapOptions::default()
    };
    build_from_images(&sources, ImageLayout::Sequence, &options, &mut |_, _, _| {
        true
    })
    .unwrap()
    .0
}
