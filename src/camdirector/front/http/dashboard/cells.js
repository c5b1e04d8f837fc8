// A table row's cell, its text written with textContent, never as HTML.
export function cell(row, text) {
  const td = document.createElement("td");
  td.textContent = text;
  row.appendChild(td);
  return td;
}
