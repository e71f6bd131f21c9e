// Telling a binary file from scene text before it reaches the editor, by the
// rule the server's parser uses (src/scene/lines.rs): a control byte other than
// TAB, LF and CR, or DEL, among the first BINARY_SNIFF_BYTES.
import { BINARY_SNIFF_BYTES } from './limits.js';

// Signatures of files users are likely to open by mistake, to name what they opened.
const SIGNATURES = [
  { name: 'a PNG image', bytes: [0x89, 0x50, 0x4e, 0x47] },
  { name: 'a JPEG image', bytes: [0xff, 0xd8, 0xff] },
  { name: 'a GIF image', bytes: [0x47, 0x49, 0x46, 0x38] },
  { name: 'a PDF document', bytes: [0x25, 0x50, 0x44, 0x46] },
  { name: 'a ZIP archive', bytes: [0x50, 0x4b, 0x03, 0x04] },
  { name: 'a gzip archive', bytes: [0x1f, 0x8b] },
  { name: 'an executable (ELF)', bytes: [0x7f, 0x45, 0x4c, 0x46] },
];

function isControl(byte) {
  return (byte < 0x20 && byte !== 0x09 && byte !== 0x0a && byte !== 0x0d) || byte === 0x7f;
}

// What the first bytes of a file are when they are not text ("a PNG image",
// or "binary data"), or null when they may be a scene.
export function binaryKind(bytes) {
  if (!bytes.subarray(0, BINARY_SNIFF_BYTES).some(isControl)) return null;
  const known = SIGNATURES.find((s) => s.bytes.every((b, i) => bytes[i] === b));
  return known ? known.name : 'binary data';
}
