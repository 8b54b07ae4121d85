//! The administration page and its forms.

use super::*;

struct RunnerRow {
    name: String,
    machine: String,
    healthy: bool,
    /// Why it is not handed the current season's benchmarks, when it is not.
    held: Option<String>,
    last_seen: String,
    running_jobs: i64,
}

#[derive(Template)]
#[template(path = "admin.html")]
struct AdminPage {
    nav: Nav,
    runners: Vec<RunnerRow>,
    jobs: Vec<JobRow>,
    season: i64,
    /// The class the current season's times come from, once named.
    season_class: Option<String>,
    /// The classes of the registered runners, for the new season's.
    runner_classes: Vec<String>,
}

fn admin_of(nav: &Nav) -> Result<&User, PageError> {
    match &nav.user {
        Some(u) if u.is_admin => Ok(u),
        Some(_) => Err(ApiError::forbidden("not_admin", "only administrators can see this page").into()),
        None => Err(ApiError::unauthorized("log in first").into()),
    }
}

/// `GET /admin`.
pub async fn admin_page(State(state): State<AppState>, Visitor(nav): Visitor) -> PageResult {
    admin_of(&nav)?;
    let now = crate::now_ms();
    let all = crate::runners::all(&state.pool).await?;
    let season = crate::results::current_season(&state.pool).await?;
    let season_data = state.boards.season(&state.pool, season).await?;
    let runner_classes: Vec<String> = all
        .iter()
        .filter_map(|r| crate::results::runner_class(&r.machine).map(str::to_string))
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    let runners = all
        .into_iter()
        .map(|r| RunnerRow {
            healthy: r.healthy(&state.config, now),
            held: season_data.drift_of(&r.machine).map(|d| {
                format!(
                    "held back from season {season}'s benchmarks: its calibration is off its class's ({})",
                    d.figures()
                )
            }),
            name: r.name,
            machine: r.machine.to_string(),
            last_seen: when(r.last_seen_at),
            running_jobs: r.running_jobs,
        })
        .collect();
    let jobs = crate::jobs::all(&state.pool, 200).await?.iter().map(job_row).collect();
    let season_class = crate::results::season_class(&state.pool, season).await?;
    Ok(render(&AdminPage { nav, runners, jobs, season, season_class, runner_classes }))
}

/// `POST /admin/jobs/{id}/requeue`.
pub async fn admin_requeue(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Button { user, nav }: Button,
) -> PageResult {
    admin_of(&nav)?;
    crate::jobs::requeue(&state.pool, &id, &user.email).await?;
    state.job_queued.notify_waiters();
    Ok(Redirect::to("/admin").into_response())
}

/// The hide form.
#[derive(Deserialize)]
pub struct HideForm {
    csrf_token: String,
    result_id: String,
    reason: String,
}

/// `POST /admin/hide`.
pub async fn admin_hide(
    State(state): State<AppState>,
    visitor: Visitor,
    PageForm(form): PageForm<HideForm>,
) -> PageResult {
    visitor.check(&form.csrf_token)?;
    admin_of(&visitor.0)?;
    if form.reason.trim().is_empty() {
        return Err(ApiError::bad_request("missing_reason", "say why the result set is hidden").into());
    }
    if !crate::results::set_hidden(&state.pool, form.result_id.trim(), Some(form.reason.trim())).await? {
        return Err(
            ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no result set {}", form.result_id)).into()
        );
    }
    Ok(Redirect::to("/admin").into_response())
}

/// The new-season form.
#[derive(Deserialize)]
pub struct SeasonForm {
    csrf_token: String,
    note: String,
    /// Empty: the season's first result names it.
    #[serde(default)]
    runner_class: String,
}

/// `POST /admin/seasons`.
pub async fn admin_season(
    State(state): State<AppState>,
    visitor: Visitor,
    PageForm(form): PageForm<SeasonForm>,
) -> PageResult {
    visitor.check(&form.csrf_token)?;
    admin_of(&visitor.0)?;
    let started = crate::admin::start_season(&state, &form.note, Some(&form.runner_class)).await?;
    let text = format!("Season {} started; {} techniques queued again.", started.season, started.queued.len());
    Ok(message(visitor.0, "New season", text))
}
