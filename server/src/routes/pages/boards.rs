//! The leaderboard (also the home page) and private results pages.

use super::*;

/// `GET /`: the leaderboard, with how to submit while it is empty and what
/// the service is still preparing.
pub async fn home(State(state): State<AppState>, Visitor(nav): Visitor, Query(query): Query<BoardQuery>) -> PageResult {
    board_page(&state, nav, query, None, true).await
}

struct EntryView {
    technique: String,
    highlighted: bool,
    status: String,
    message: String,
    values: Vec<String>,
    /// "= beta, gamma" when it ties by the sort metric, else empty.
    tied: String,
    time: String,
    cost: String,
    image: String,
}

struct GroupView {
    scene: String,
    tags: Vec<String>,
    spp: i64,
    entries: Vec<EntryView>,
}

struct StandingView {
    technique: String,
    full_name: String,
    citation: String,
    result_id: String,
    highlighted: bool,
    mean_rank: String,
    mean_rank_time: String,
    tied: usize,
    missing: usize,
}

struct ResultView {
    id: String,
    technique: String,
    full_name: String,
    commit: String,
    season: i64,
    created: String,
    published: bool,
    hidden_reason: String,
    owner: bool,
    provenance: String,
}

#[derive(Template)]
#[template(path = "board.html")]
struct BoardPage {
    nav: Nav,
    title: String,
    result: Option<ResultView>,
    seasons: Vec<(i64, String)>,
    season: i64,
    metrics: Vec<fbksd_exchange::MetricInfo>,
    sort: String,
    tags: Vec<String>,
    tag: String,
    tag_query: String,
    standings: Vec<StandingView>,
    groups: Vec<GroupView>,
    /// Scenes whose runs against an earlier reference were left out.
    left_out: Vec<String>,
    /// The runner class the season's times come from (empty: none named yet).
    runner_class: String,
    /// Shown on the public board while it is empty.
    how_to: Option<HowTo>,
    /// What the service still prepares (home page only).
    preparing: Vec<String>,
    /// The results viewer's scripts (result pages).
    viewer_tags: String,
}

async fn board_page(
    state: &AppState,
    nav: Nav,
    query: BoardQuery,
    result: Option<crate::results::ResultSet>,
    home: bool,
) -> PageResult {
    Ok(render(&board_template(state, nav, query, result, home).await?))
}

async fn board_template(
    state: &AppState,
    nav: Nav,
    query: BoardQuery,
    result: Option<crate::results::ResultSet>,
    home: bool,
) -> Result<BoardPage, PageError> {
    let query = BoardQuery { tag: query.tag.filter(|t| !t.is_empty()), ..query };
    let board = leaderboard::build(&state.pool, &state.boards, &query, result.as_ref()).await?;
    let seasons = crate::results::seasons(&state.pool).await?.into_iter().map(|(n, note, _)| (n, note)).collect();
    let title = match &result {
        Some(r) => format!("Results of {}", r.full_name()),
        None => format!("Leaderboard, season {}", board.season),
    };
    let result = result.map(|r| ResultView {
        owner: nav.user.as_ref().is_some_and(|u| r.user_id.as_deref() == Some(u.id.as_str())),
        full_name: r.full_name().to_string(),
        id: r.id,
        technique: r.technique,
        commit: r.commit_sha,
        season: r.season,
        created: when(r.created_at),
        published: r.published_at.is_some(),
        hidden_reason: r.hidden_reason.unwrap_or_default(),
        provenance: serde_json::to_string_pretty(&r.provenance).unwrap_or_default(),
    });
    // A result page shows the viewer instead of the per-scene tables.
    let tabled: &[leaderboard::Group] = if result.is_some() { &[] } else { &board.groups };
    let groups = tabled
        .iter()
        .map(|g| GroupView {
            entries: g
                .entries
                .iter()
                .map(|e| EntryView {
                    // The viewer of the entry's set, opened on this scene and spp.
                    image: e
                        .image
                        .as_ref()
                        .map(|_| format!("/results/{}#scene={}&spp={}", e.result_id, g.scene, g.spp))
                        .unwrap_or_default(),
                    // Full names need not be unique: the project's name tells them apart.
                    technique: format!("{} ({})", e.full_name, e.technique),
                    highlighted: e.highlighted,
                    status: e.status.clone(),
                    message: e.message.clone(),
                    values: e
                        .values
                        .iter()
                        .zip(&e.intervals)
                        .map(|(v, i)| match i {
                            Some(i) => format!("{} ± {}", number(*v), number(Some(i.half_width()))),
                            None => number(*v),
                        })
                        .collect(),
                    tied: if e.tied_with.is_empty() { String::new() } else { e.tied_with.join(", ") },
                    time: match e.time_cv {
                        Some(cv) => format!("{:.1} ms (CV {:.1} %)", e.technique_ms, cv * 100.0),
                        None => format!("{:.1} ms", e.technique_ms),
                    },
                    cost: if e.cost_ms.is_finite() {
                        format!("{:.1} ms", e.cost_ms)
                    } else {
                        "other runner class".into()
                    },
                })
                .collect(),
            scene: g.scene.clone(),
            tags: g.tags.clone(),
            spp: g.spp,
        })
        .collect();
    let standings: Vec<StandingView> = board
        .standings
        .iter()
        .map(|s| StandingView {
            technique: s.technique.clone(),
            full_name: s.full_name.clone(),
            citation: s.citation.clone(),
            result_id: s.result_id.clone(),
            highlighted: s.highlighted,
            mean_rank: format!("{:.2}", s.mean_rank),
            mean_rank_time: if s.mean_rank_time.is_finite() {
                format!("{:.2}", s.mean_rank_time)
            } else {
                "—".into()
            },
            tied: s.tied,
            missing: s.missing,
        })
        .collect();
    let tag = board.tag.clone().unwrap_or_default();
    // The home page alone says what is being prepared: the leaderboard's
    // own address stays one cached board and no query.
    let how_to = (result.is_none() && standings.is_empty()).then(|| how_to(state, nav.user.as_ref(), None));
    let preparing = if home { preparation(state, nav.user.as_ref()).await? } else { Vec::new() };
    let page = BoardPage {
        how_to,
        preparing,
        nav,
        title,
        result,
        seasons,
        season: board.season,
        metrics: board.metrics.clone(),
        sort: board.sort.clone(),
        tags: board.tags.clone(),
        tag_query: if tag.is_empty() { String::new() } else { format!("&tag={tag}") },
        tag,
        standings,
        groups,
        left_out: board.left_out.clone(),
        runner_class: board.runner_class.clone().unwrap_or_default(),
        viewer_tags: fbksd_exchange::viewer::asset_tags("/static/viewer/"),
    };
    Ok(page)
}

/// `GET /results/`: the public leaderboard. Anonymous visitors, most of
/// its readers, all see one page per query: it is rendered once per board
/// version and revalidated by its ETag ([`crate::routes::PublicBoards`]).
pub async fn leaderboard_page(
    State(state): State<AppState>,
    Visitor(nav): Visitor,
    Query(query): Query<BoardQuery>,
    headers: axum::http::HeaderMap,
) -> PageResult {
    if nav.user.is_some() {
        return board_page(&state, nav, query, None, false).await;
    }
    let query = BoardQuery { tag: query.tag.filter(|t| !t.is_empty()), ..query };
    let render = async {
        let page = board_template(&state, nav, query.clone(), None, false).await.map_err(|e| e.0)?;
        page.render().map_err(ApiError::internal)
    };
    Ok(state
        .public_boards
        .respond(&state.boards, &state.pool, crate::routes::Rendering::Html, &query, &headers, render)
        .await?)
}

/// `GET /results/{id}`: a result set beside every published technique.
pub async fn result_page(
    State(state): State<AppState>,
    Visitor(nav): Visitor,
    Path(id): Path<String>,
    Query(query): Query<BoardQuery>,
) -> PageResult {
    let set = crate::results::visible(&state.pool, &id, nav.user.as_ref()).await?;
    board_page(&state, nav, query, Some(set), false).await
}

/// `POST /results/{id}/{action}`: publish, unpublish or discard (owner only).
pub async fn result_action(
    State(state): State<AppState>,
    Path((id, action)): Path<(String, String)>,
    Button { user, nav }: Button,
) -> PageResult {
    let set = crate::results::owned(&state.pool, &id, &user.id).await?;
    match action.as_str() {
        "publish" => crate::results::publish(&state.pool, &set).await?,
        "unpublish" => crate::results::unpublish(&state.pool, &set.id).await?,
        "discard" => {
            crate::results::discard(&state.pool, &state.config.data_dir, &set.id).await?;
            return Ok(message(nav, "Discarded", format!("Result set {id} is deleted.")));
        }
        other => return Err(ApiError::new(StatusCode::NOT_FOUND, "not_found", format!("no action {other:?}")).into()),
    }
    Ok(Redirect::to(&format!("/results/{id}")).into_response())
}
