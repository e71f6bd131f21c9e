// Between PNG files and exact RGB pixels, in the browser. The server's PNGs
// carry no colour profile or gamma and no alpha, so with colour conversion and
// premultiplication off the decoded bytes are the rendered bytes; the
// Framebuffer refuses a tile whose alpha says otherwise.

// A PNG blob as ImageData (RGBA, top row first).
export async function decodePng(blob) {
  const bitmap = await createImageBitmap(blob, { premultiplyAlpha: 'none', colorSpaceConversion: 'none' });
  try {
    const canvas = new OffscreenCanvas(bitmap.width, bitmap.height);
    const ctx = canvas.getContext('2d', { willReadFrequently: true });
    ctx.drawImage(bitmap, 0, 0);
    return ctx.getImageData(0, 0, bitmap.width, bitmap.height);
  } finally {
    bitmap.close();
  }
}

// The framebuffer as a PNG blob, encoded by the browser from its exact pixels.
export function encodePng(frame) {
  const rgba = new Uint8ClampedArray(frame.width * frame.height * 4);
  for (let from = 0, to = 0; from < frame.rgb.length; from += 3, to += 4) {
    rgba[to] = frame.rgb[from];
    rgba[to + 1] = frame.rgb[from + 1];
    rgba[to + 2] = frame.rgb[from + 2];
    rgba[to + 3] = 255;
  }
  const canvas = new OffscreenCanvas(frame.width, frame.height);
  canvas.getContext('2d').putImageData(new ImageData(rgba, frame.width, frame.height), 0, 0);
  return canvas.convertToBlob({ type: 'image/png' });
}
