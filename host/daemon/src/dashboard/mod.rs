//! The dashboard: one static page (HTML, JS, CSS compiled into the binary) that reads `/api/v1/stream`,
//! `/api/v1/frame.jpg` and `/api/v1/status`, draws the lattice, shear and contacts of each shown frame's own
//! reading over it, and drives `/api/v1/tare`, `/api/v1/led` and `/api/v1/record`. No build step.

use axum::http::header;
use axum::response::IntoResponse;

const INDEX_HTML: &str = include_str!("index.html");
const DASHBOARD_JS: &str = include_str!("dashboard.js");
const DASHBOARD_CSS: &str = include_str!("dashboard.css");

pub async fn index() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], INDEX_HTML)
}

pub async fn script() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/javascript; charset=utf-8")], DASHBOARD_JS)
}

pub async fn style() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], DASHBOARD_CSS)
}
