//! The plot as PNG: its SVG rasterised by resvg at [`SCALE`] times its size. The text is set in
//! one embedded font (Ubuntu Light, from egui's font crate), never the machine's, so the
//! picture is the same on every machine, fonts installed or not.

/// Pixels per SVG unit: 960 units wide gives a 1920-pixel picture, sharp on a dense screen.
pub const SCALE: f32 = 2.0;

#[derive(Debug, thiserror::Error)]
pub enum PngError {
    #[error("the plot's SVG did not parse: {0}")]
    Svg(#[from] resvg::usvg::Error),
    #[error("a {0}×{1} picture is too large to rasterise")]
    Size(u32, u32),
    #[error("PNG encoding failed: {0}")]
    Encode(String),
}

/// The PNG of an SVG document.
pub fn from_svg(svg: &str) -> Result<Vec<u8>, PngError> {
    let mut options = resvg::usvg::Options::default();
    let fonts = options.fontdb_mut();
    fonts.load_font_data(epaint_default_fonts::UBUNTU_LIGHT.to_vec());
    let family = fonts
        .faces()
        .next()
        .and_then(|face| face.families.first())
        .map(|(name, _)| name.clone())
        .unwrap_or_default();
    fonts.set_sans_serif_family(family.clone());
    options.font_family = family;
    let tree = resvg::usvg::Tree::from_str(svg, &options)?;
    let size = tree.size().to_int_size().scale_by(SCALE);
    let (w, h) = size.map_or((0, 0), |s| (s.width(), s.height()));
    let mut pixmap = resvg::tiny_skia::Pixmap::new(w, h).ok_or(PngError::Size(w, h))?;
    resvg::render(
        &tree,
        resvg::tiny_skia::Transform::from_scale(SCALE, SCALE),
        &mut pixmap.as_mut(),
    );
    // Straight (not premultiplied) RGBA, as PNG stores it.
    let mut rgba = Vec::with_capacity(pixmap.data().len());
    for p in pixmap.pixels() {
        let c = p.demultiply();
        rgba.extend_from_slice(&[c.red(), c.green(), c.blue(), c.alpha()]);
    }
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, w, h);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Best);
    encoder.set_adaptive_filter(png::AdaptiveFilterType::Adaptive);
    let encode = |encoder: png::Encoder<'_, &mut Vec<u8>>| -> Result<(), png::EncodingError> {
        let mut writer = encoder.write_header()?;
        writer.write_image_data(&rgba)?;
        writer.finish()
    };
    encode(encoder).map_err(|e| PngError::Encode(e.to_string()))?;
    Ok(out)
}

/// Is this path meant for a PNG (its extension, in any case)?
pub fn is_png(path: &std::path::Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The PNG's width and height, read from its signature and IHDR by hand.
    fn header(png: &[u8]) -> (u32, u32) {
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
        assert_eq!(&png[12..16], b"IHDR");
        let be = |b: &[u8]| u32::from_be_bytes(b.try_into().unwrap());
        (be(&png[16..20]), be(&png[20..24]))
    }

    #[test]
    fn the_picture_is_the_svg_at_twice_its_size_and_its_text_is_drawn() {
        let blank = r#"<svg xmlns="http://www.w3.org/2000/svg" width="120" height="40" font-family="sans-serif"><rect width="100%" height="100%" fill="white"/></svg>"#;
        let text = blank.replace(
            "</svg>",
            r#"<text x="4" y="28" font-size="20">gamma</text></svg>"#,
        );
        let (a, b) = (from_svg(blank).unwrap(), from_svg(&text).unwrap());
        assert_eq!(header(&a), (240, 80));
        assert_eq!(header(&b), (240, 80));
        // The text's pixels make the picture differ: the embedded font was found for
        // "sans-serif" (with no font, resvg drops text silently).
        let dark = |png: &[u8]| {
            let pixmap = resvg::tiny_skia::Pixmap::decode_png(png).unwrap();
            pixmap
                .pixels()
                .iter()
                .filter(|p| p.red() < 128 && p.alpha() > 0)
                .count()
        };
        assert_eq!(dark(&a), 0);
        assert!(dark(&b) > 200, "{} dark pixels", dark(&b));
    }

    #[test]
    fn a_broken_svg_is_an_error() {
        assert!(matches!(from_svg("<svg"), Err(PngError::Svg(_))));
    }

    #[test]
    fn png_is_told_by_the_extension() {
        assert!(is_png(std::path::Path::new("a/b.PNG")));
        assert!(!is_png(std::path::Path::new("b.svg")));
        assert!(!is_png(std::path::Path::new("png")));
    }
}
