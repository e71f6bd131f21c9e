// What the page reads from the scene text before it renders: the dialect (for
// the defaults it shows) and the resolution (to cut the image into tiles). The
// server parses the scene in full; when these cannot tell, the page asks it
// for the whole image and shows what it says.
import { DEFAULT_BROWSER_DEPTH, DEFAULT_CLASSIC_DEPTH, DEFAULT_SPP } from './limits.js';

// The lines of the text as docs/scene-format.md splits them: LF or CRLF, `#`
// comments dropped, tokens between runs of spaces and TABs.
function* directives(text) {
  // By index rather than split, so that reading the first SPHERE line of a
  // scene of millions stops there.
  for (let start = 0; start < text.length;) {
    let end = text.indexOf('\n', start);
    if (end < 0) end = text.length;
    const raw = text.slice(start, end);
    start = end + 1;
    const hash = raw.indexOf('#');
    const line = hash >= 0 ? raw.slice(0, hash) : raw;
    const tokens = line.split(/[ \t\r]+/).filter((t) => t !== '');
    if (tokens.length) yield { keyword: tokens[0].toUpperCase(), args: tokens.slice(1) };
  }
}

// The parser's test for a number where a classic line has its name.
function looksNumeric(token) {
  return /^[0-9+\-.]/.test(token) || Number.isFinite(Number(token)) || /^[+-]?(inf|infinity|nan)$/i.test(token);
}

// "classic" or "browser", told as the parser tells it: from the first SPHERE or
// LIGHT line, whose second token is a name only in the classic dialect. A
// scene with neither is classic.
export function sceneDialect(text) {
  for (const { keyword, args } of directives(text)) {
    if (keyword === 'SPHERE' || keyword === 'LIGHT') {
      return args.length && !looksNumeric(args[0]) ? 'classic' : 'browser';
    }
  }
  return 'classic';
}

// The defaults a render of a scene of `dialect` uses when the query names none.
export function dialectDefaults(dialect) {
  const depth = dialect === 'browser' ? DEFAULT_BROWSER_DEPTH : DEFAULT_CLASSIC_DEPTH;
  return { spp: DEFAULT_SPP, depth };
}

// { width, height } of the one well-formed RES line, or null (none, several,
// or values the parser would refuse, which the server then names).
export function sceneResolution(text) {
  const found = [];
  for (const { keyword, args } of directives(text)) {
    if (keyword === 'RES') found.push(args);
  }
  if (found.length !== 1 || found[0].length !== 2) return null;
  const [width, height] = found[0].map(Number);
  const whole = (n) => Number.isInteger(n) && n > 0;
  return whole(width) && whole(height) ? { width, height } : null;
}
