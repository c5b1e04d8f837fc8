// In the header: the server's refusal, or that it could not be reached. A 401 is the login form's
// to say (api.js hands it there).
import { ApiError } from "./api.js";

export function showTrouble(error) {
  if (error instanceof ApiError && error.status === 401) return;
  document.getElementById("health").textContent =
    error instanceof ApiError ? error.message : `unreachable: ${error.message}`;
}
