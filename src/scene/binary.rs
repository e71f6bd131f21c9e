//! What marks a text as binary data rather than a scene: control bytes, and
//! the first bytes of the file kinds people open by mistake (the image they
//! rendered, an executable), which name the kind in the message.

/// A byte no scene text holds: C0 controls but TAB, LF and CR (a lone CR is
/// how old Mac files end lines), and DEL.
pub(super) fn is_control(byte: u8) -> bool {
    (byte < 0x20 && !matches!(byte, b'\t' | b'\n' | b'\r')) || byte == 0x7f
}

/// File signatures (the first bytes of a file of that kind) and the kind's
/// name. Each holds a byte that no scene's first keyword does, so no scene
/// matches one.
const SIGNATURES: [(&[u8], &str); 14] = [
    (b"\x7fELF", "an ELF executable"),
    (b"MZ\x90\x00", "a Windows executable"),
    (b"\xcf\xfa\xed\xfe", "a Mach-O executable"),
    (b"\xce\xfa\xed\xfe", "a Mach-O executable"),
    (b"\0asm", "a WebAssembly module"),
    (b"\x89PNG", "a PNG image"),
    (b"\xff\xd8\xff", "a JPEG image"),
    (b"GIF8", "a GIF image"),
    (b"%PDF-", "a PDF document"),
    (b"PK\x03\x04", "a zip archive"),
    (b"\x1f\x8b", "a gzip archive"),
    (b"\xfd7zXZ\x00", "an xz archive"),
    (b"\xff\xfe", "UTF-16 text: save the scene as UTF-8"),
    (b"\xfe\xff", "UTF-16 text: save the scene as UTF-8"),
];

/// The kind of file whose first line this is, if it starts as one of the
/// known binary kinds does, or as a PPM (`P6`, what `voxtrace render`
/// writes, fed back in).
pub(super) fn signature(first_line: &[u8]) -> Option<&'static str> {
    let ppm = first_line.strip_prefix(b"P6").is_some_and(|rest| {
        rest.first()
            .is_none_or(|b| b.is_ascii_whitespace() || *b == b'#')
    });
    if ppm {
        return Some("a PPM image");
    }
    SIGNATURES
        .iter()
        .find(|(magic, _)| first_line.starts_with(magic))
        .map(|&(_, name)| name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_kinds_are_named_and_scenes_are_not() {
        assert_eq!(signature(b"\x7fELF\x02\x01\x01"), Some("an ELF executable"));
        assert_eq!(signature(b"\x89PNG\r"), Some("a PNG image"));
        assert_eq!(signature(b"P6"), Some("a PPM image"));
        assert_eq!(signature(b"P6 600 600 255"), Some("a PPM image"));
        assert_eq!(signature(b"P64"), None);
        for scene in [&b"NEAR 1"[..], b"# P6", b"", b"PK", b"GIF"] {
            assert_eq!(signature(scene), None, "{scene:?}");
        }
    }

    #[test]
    fn controls_are_all_c0_but_blanks_and_line_ends_and_del() {
        let controls: Vec<u8> = (0..=255).filter(|&b| is_control(b)).collect();
        let mut expected: Vec<u8> = (0..0x20).filter(|b| ![9, 10, 13].contains(b)).collect();
        expected.push(0x7f);
        assert_eq!(controls, expected);
    }
}
