//! The HTTP interface: routes, authentication, body limits (size, and the time to send it)
//! and the headers every response carries. Each handler checks the token and runs the [`App`]
//! call on the blocking pool (either may wait for a session lock, an fsync or the database).
//!
//! | route | what |
//! | --- | --- |
//! | `GET /`, `GET /{file}` | the built page |
//! | `GET /api/study` | title and what the browser must offer (before joining) |
//! | `POST /api/join` | a new participant (URL ids, environment) → subject and token |
//! | `GET /api/s/{subject}/session` | the screens' texts, scale, state |
//! | `POST /api/s/{subject}/begin` | fields, consent, environment: the session begins |
//! | `GET /api/s/{subject}/trial` | the pending or next trial, or `done` |
//! | `GET /api/s/{subject}/clip/{index}/{slot}` | joint positions of a pending trial's clip |
//! | `POST /api/s/{subject}/answer` | an answer, acknowledged once it is on disk |
//! | `GET /api/dashboard` | the experimenter's view (dashboard token) |

use std::collections::BTreeMap;
use std::sync::Arc;

use axum::Json;
use axum::Router;
use axum::body::Body;
use axum::extract::rejection::JsonRejection;
use axum::extract::{DefaultBodyLimit, Path, Request, State};
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde::Deserialize;

use crate::app::{AnswerRequest, ApiError, App, BeginRequest, Environment};

type Shared = State<Arc<App>>;

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = StatusCode::from_u16(self.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        (status, Json(serde_json::json!({ "error": self.message }))).into_response()
    }
}

fn bad_json(e: &JsonRejection) -> ApiError {
    ApiError::new(e.status().as_u16(), e.body_text())
}

/// Runs `f` on the blocking pool.
async fn blocking<T: Send + 'static>(
    f: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
) -> Result<T, ApiError> {
    tokio::task::spawn_blocking(f)
        .await
        .map_err(|e| ApiError::new(500, format!("the request failed: {e}")))?
}

fn bearer(headers: &HeaderMap) -> Result<&str, ApiError> {
    headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
        .ok_or_else(|| ApiError::new(401, "no session token"))
}

/// The routes over `app`.
pub(crate) fn router(app: Arc<App>) -> Router {
    let limit = app.limits().max_body_bytes;
    Router::new()
        .route("/", get(index))
        .route("/{file}", get(page_file))
        .route("/api/study", get(study))
        .route("/api/join", post(join))
        .route("/api/s/{subject}/session", get(session))
        .route("/api/s/{subject}/begin", post(begin))
        .route("/api/s/{subject}/trial", get(trial))
        .route("/api/s/{subject}/clip/{index}/{slot}", get(clip))
        .route("/api/s/{subject}/answer", post(answer))
        .route("/api/dashboard", get(dashboard))
        .layer(DefaultBodyLimit::max(limit))
        .layer(axum::middleware::from_fn_with_state(
            Arc::clone(&app),
            read_body,
        ))
        .layer(axum::middleware::map_response(security_headers))
        .with_state(app)
}

/// Reads a request's whole body (at most the body limit) within the body timeout before the
/// handler sees it: a client that sends it too slowly is answered 408, one over the limit
/// 413, and neither holds a handler meanwhile.
async fn read_body(State(app): Shared, req: Request, next: Next) -> Response {
    let limits = *app.limits();
    let (parts, body) = req.into_parts();
    let declared = parts
        .headers
        .get(header::CONTENT_LENGTH)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<u64>().ok());
    let too_large = || {
        ApiError::new(
            413,
            format!("the request body is over {} bytes", limits.max_body_bytes),
        )
        .into_response()
    };
    if declared.is_some_and(|n| n > limits.max_body_bytes as u64) {
        return too_large();
    }
    let read = axum::body::to_bytes(body, limits.max_body_bytes);
    match tokio::time::timeout(limits.body_timeout, read).await {
        Ok(Ok(bytes)) => {
            next.run(Request::from_parts(parts, Body::from(bytes)))
                .await
        }
        // Over the limit without a length given, or cut off (then nobody reads the reply).
        Ok(Err(_)) => too_large(),
        Err(_) => ApiError::new(
            408,
            format!(
                "the request body was not sent within {} s",
                limits.body_timeout.as_secs_f64()
            ),
        )
        .into_response(),
    }
}

/// Headers on every response: no caching of session data, no sniffing, no referrer (the
/// token is in the URL fragment, which is never sent, but the subject id is in the query),
/// no framing, and only the page's own scripts.
async fn security_headers(mut r: Response) -> Response {
    let h = r.headers_mut();
    h.insert(header::CACHE_CONTROL, HeaderValue::from_static("no-store"));
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    h.insert(
        header::REFERRER_POLICY,
        HeaderValue::from_static("no-referrer"),
    );
    h.insert(header::X_FRAME_OPTIONS, HeaderValue::from_static("DENY"));
    h.insert(
        header::CONTENT_SECURITY_POLICY,
        HeaderValue::from_static(
            "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data:; \
             connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'none'",
        ),
    );
    r
}

async fn index(State(app): Shared) -> Response {
    serve_file(&app, "index.html")
}

async fn page_file(State(app): Shared, Path(file): Path<String>) -> Response {
    serve_file(&app, &file)
}

fn serve_file(app: &App, name: &str) -> Response {
    match app.page_file(name) {
        Some((kind, bytes)) => {
            ([(header::CONTENT_TYPE, kind)], bytes.as_ref().clone()).into_response()
        }
        None => ApiError::new(404, "not found").into_response(),
    }
}

async fn study(State(app): Shared) -> Response {
    Json(app.public_info()).into_response()
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JoinRequest {
    params: BTreeMap<String, String>,
    environment: Environment,
}

async fn join(
    State(app): Shared,
    body: Result<Json<JoinRequest>, JsonRejection>,
) -> Result<Response, ApiError> {
    let Json(req) = body.map_err(|e| bad_json(&e))?;
    if req.params.len() > 16 {
        return Err(ApiError::new(400, "too many URL parameters"));
    }
    let (subject, token) = blocking(move || app.join(&req.params, &req.environment)).await?;
    Ok(Json(serde_json::json!({ "subject": subject, "token": token })).into_response())
}

async fn session(
    State(app): Shared,
    Path(subject): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let token = bearer(&headers)?.to_owned();
    let info = blocking(move || app.session_info(&*app.authorize(&subject, &token)?)).await?;
    Ok(Json(info).into_response())
}

async fn begin(
    State(app): Shared,
    Path(subject): Path<String>,
    headers: HeaderMap,
    body: Result<Json<BeginRequest>, JsonRejection>,
) -> Result<Response, ApiError> {
    let token = bearer(&headers)?.to_owned();
    blocking(move || {
        let p = app.authorize(&subject, &token)?;
        let Json(req) = body.map_err(|e| bad_json(&e))?;
        app.begin(&p, &req)
    })
    .await?;
    Ok(Json(serde_json::json!({ "begun": true })).into_response())
}

async fn trial(
    State(app): Shared,
    Path(subject): Path<String>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let token = bearer(&headers)?.to_owned();
    let info = blocking(move || app.trial(&*app.authorize(&subject, &token)?)).await?;
    Ok(Json(info).into_response())
}

async fn clip(
    State(app): Shared,
    Path((subject, index, slot)): Path<(String, u32, usize)>,
    headers: HeaderMap,
) -> Result<Response, ApiError> {
    let token = bearer(&headers)?.to_owned();
    let bytes = blocking(move || app.clip(&*app.authorize(&subject, &token)?, index, slot)).await?;
    Ok((
        [(header::CONTENT_TYPE, "application/octet-stream")],
        bytes.as_ref().clone(),
    )
        .into_response())
}

async fn answer(
    State(app): Shared,
    Path(subject): Path<String>,
    headers: HeaderMap,
    body: Result<Json<AnswerRequest>, JsonRejection>,
) -> Result<Response, ApiError> {
    let token = bearer(&headers)?.to_owned();
    let reply = blocking(move || {
        let p = app.authorize(&subject, &token)?;
        let Json(req) = body.map_err(|e| bad_json(&e))?;
        app.answer(&p, &req)
    })
    .await?;
    Ok(Json(reply).into_response())
}

async fn dashboard(State(app): Shared, headers: HeaderMap) -> Result<Response, ApiError> {
    if !app.dashboard_allows(bearer(&headers)?) {
        return Err(ApiError::new(403, "not the dashboard's token"));
    }
    let info = blocking(move || app.dashboard()).await?;
    Ok(Json(info).into_response())
}
