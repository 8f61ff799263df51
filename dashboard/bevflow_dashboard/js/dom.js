// Small helpers for building DOM nodes without innerHTML (ids and names from the site file are
// inserted as text, never parsed as markup).

/** An element with attributes (`class`, `data-*`, `aria-*`, properties like `onclick`) and children. */
export function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [name, value] of Object.entries(attrs)) {
    if (value === undefined || value === null || value === false) continue;
    if (name.startsWith("on") && typeof value === "function") node.addEventListener(name.slice(2), value);
    else if (name === "class") node.className = value;
    else if (name === "hidden") node.hidden = Boolean(value);
    else node.setAttribute(name, value === true ? "" : String(value));
  }
  for (const child of children.flat()) {
    if (child === undefined || child === null || child === false) continue;
    node.append(child instanceof Node ? child : document.createTextNode(String(child)));
  }
  return node;
}

/** Replace all of `node`'s children. */
export function replaceChildren(node, children) {
  node.replaceChildren(...children.filter((c) => c !== null && c !== undefined));
}

/** A CSS custom property of the document, e.g. `cssColor("--level-over")`. */
export function cssColor(name) {
  return getComputedStyle(document.documentElement).getPropertyValue(name).trim() || "#888888";
}

/** `#rrggbb` with an alpha, as `rgba(...)`. */
export function withAlpha(hex, alpha) {
  const n = parseInt(hex.slice(1), 16);
  return `rgba(${(n >> 16) & 255}, ${(n >> 8) & 255}, ${n & 255}, ${Math.max(0, Math.min(1, alpha))})`;
}
