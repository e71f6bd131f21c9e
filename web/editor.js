// The scene editor: a textarea with line numbers and one highlighted line.

export class Editor {
  constructor({ textarea, gutter, lineMark }) {
    this.textarea = textarea;
    this.gutter = gutter;
    this.lineMark = lineMark;
    this.shownLines = 0;
    this.badLine = 0;
    // Bumped on every change, so that a sample arriving late never overwrites newer text.
    this.version = 0;
    textarea.addEventListener('input', () => {
      this.version++;
      this.badLine = 0;
      this.updateGutter();
    });
    textarea.addEventListener('scroll', () => this.syncScroll());
    this.updateGutter();
  }

  get text() {
    return this.textarea.value;
  }

  set(text) {
    this.version++;
    this.textarea.value = text;
    this.textarea.scrollTop = 0;
    this.badLine = 0;
    this.updateGutter();
  }

  lineHeight() {
    return parseFloat(getComputedStyle(this.textarea).lineHeight) || 20;
  }

  updateGutter() {
    const lines = this.text.split('\n').length;
    if (lines !== this.shownLines) {
      this.shownLines = lines;
      const frag = document.createDocumentFragment();
      for (let i = 1; i <= lines; i++) {
        const div = document.createElement('div');
        div.textContent = i;
        frag.append(div);
      }
      this.gutter.replaceChildren(frag);
    }
    this.gutter.querySelectorAll('.bad').forEach((el) => el.classList.remove('bad'));
    if (this.badLine > 0 && this.badLine <= lines) this.gutter.children[this.badLine - 1].classList.add('bad');
    this.syncScroll();
  }

  syncScroll() {
    this.gutter.scrollTop = this.textarea.scrollTop;
    this.lineMark.hidden = this.badLine === 0;
    this.lineMark.style.transform = `translateY(${(this.badLine - 1) * this.lineHeight() - this.textarea.scrollTop}px)`;
  }

  // Highlights line `line` (1-based), selects it and scrolls it into view; 0 clears.
  markLine(line) {
    const lines = this.text.split('\n');
    this.badLine = Math.min(line, lines.length);
    this.updateGutter();
    if (!this.badLine) return;
    const start = lines.slice(0, this.badLine - 1).reduce((n, l) => n + l.length + 1, 0);
    this.textarea.focus({ preventScroll: true });
    this.textarea.setSelectionRange(start, start + lines[this.badLine - 1].replace(/\r$/, '').length);
    this.textarea.scrollTop = Math.max(0, (this.badLine - 1) * this.lineHeight() - this.textarea.clientHeight / 3);
    this.syncScroll();
  }
}
