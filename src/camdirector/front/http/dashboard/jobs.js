// Motion overview jobs: the tenant's jobs (GET /v1/overview-jobs), a BVH clip submitted, and a
// finished job's preview and contact sheet.
import { api } from "./api.js";
import { cell } from "./cells.js";
import { state } from "./state.js";

export async function refreshJobs() {
  const who = state.caller;
  const { jobs } = await api("/v1/overview-jobs?limit=50");
  if (state.caller !== who) return;   // logged out meanwhile: the list was the last key's
  const body = document.querySelector("#jobs tbody");
  body.replaceChildren();
  for (const j of jobs) {
    const row = document.createElement("tr");
    row.dataset.job = j.id;
    cell(row, j.id.slice(0, 12));
    cell(row, j.file_name);
    cell(row, j.frames);
    cell(row, j.error ? `${j.status}: ${j.error}` : j.status).dataset.status = j.status;
    cell(row, `${Math.round(j.progress * 100)}%`);
    const result = cell(row, "");
    if (j.status === "succeeded") {
      const view = document.createElement("button");
      view.textContent = "view";
      view.addEventListener("click", () => showJob(j.id));
      result.appendChild(view);
    }
    body.appendChild(row);
  }
}

function showJob(jobId) {
  document.getElementById("job-view").hidden = false;
  document.getElementById("job-video").src = `/v1/overview-jobs/${jobId}/preview.mp4`;
  document.getElementById("job-sheet").src = `/v1/overview-jobs/${jobId}/contact-sheet.png`;
}

export async function submitOverview(event) {
  event.preventDefault();
  const result = document.getElementById("overview-result");
  // Cleared first so the last answer is never read as this one's.
  result.className = "";
  result.textContent = "submitting…";
  try {
    const job = await api("/v1/overview-jobs", { method: "POST", body: new FormData(event.target) });
    result.className = "ok";
    result.textContent = `job ${job.id} ${job.status}`;
    refreshJobs();
  } catch (error) {
    result.className = "error";
    result.textContent = error.message;
  }
}
