// The image as it arrives: 8-bit RGB, top row first, the same bytes the server
// rendered, filled tile by tile, and the PPM file built from it.

export class Framebuffer {
  constructor(width, height) {
    this.width = width;
    this.height = height;
    this.rgb = new Uint8Array(width * height * 3);
  }

  // Copies an opaque RGBA tile (ImageData's layout) into the rectangle at
  // (x0, y0). Throws when a pixel is not opaque: the server's images have no
  // alpha, so a decoded alpha below 255 means the bytes were not kept.
  paste(x0, y0, width, height, rgba) {
    for (let y = 0; y < height; y++) {
      let from = y * width * 4;
      let to = ((y0 + y) * this.width + x0) * 3;
      for (let x = 0; x < width; x++, from += 4, to += 3) {
        if (rgba[from + 3] !== 255) throw new Error(`pixel (${x0 + x}, ${y0 + y}) decoded with alpha ${rgba[from + 3]}`);
        this.rgb[to] = rgba[from];
        this.rgb[to + 1] = rgba[from + 1];
        this.rgb[to + 2] = rgba[from + 2];
      }
    }
  }

  // Binary PPM with the header `voxtrace render` writes: `P6\n<W> <H>\n255\n`.
  toPpm() {
    const header = new TextEncoder().encode(`P6\n${this.width} ${this.height}\n255\n`);
    const file = new Uint8Array(header.length + this.rgb.length);
    file.set(header);
    file.set(this.rgb, header.length);
    return file;
  }
}
