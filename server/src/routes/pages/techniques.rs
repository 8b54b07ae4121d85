//! Pages of techniques (projects) and their jobs, with the live log.

use super::*;

struct ProjectRow {
    name: String,
    visibility: &'static str,
    created: String,
}

#[derive(Template)]
#[template(path = "projects.html")]
struct ProjectsPage {
    nav: Nav,
    projects: Vec<ProjectRow>,
    /// The last name shown, when more follow.
    next: Option<String>,
}

/// `GET /projects[?after=<name>]`: a page of the projects the visitor can see.
pub async fn projects_page(
    State(state): State<AppState>,
    Visitor(nav): Visitor,
    axum::extract::Query(page): axum::extract::Query<crate::routes::projects::ListPage>,
) -> PageResult {
    let (projects, more) = projects::visible(&state.pool, nav.user.as_ref(), &page.after).await?;
    let next = more.then(|| projects.last().map(|p| p.name.clone())).flatten();
    let projects = projects
        .into_iter()
        .map(|p| ProjectRow { name: p.name, visibility: p.visibility.as_str(), created: when(p.created_at) })
        .collect();
    Ok(render(&ProjectsPage { nav, projects, next }))
}

struct EnvironmentView {
    name: &'static str,
    packages: Vec<PackageView>,
}

struct PackageView {
    name: &'static str,
    version: &'static str,
    what: &'static str,
    provides: String,
}

#[derive(Template)]
#[template(path = "environments.html")]
struct EnvironmentsPage {
    nav: Nav,
    environments: Vec<EnvironmentView>,
}

/// `GET /environments`: what each build environment holds.
pub async fn environments_page(Visitor(nav): Visitor) -> PageResult {
    let environments = fbksd_exchange::technique::Environment::ALL
        .iter()
        .map(|env| EnvironmentView {
            name: env.as_str(),
            packages: env
                .packages()
                .iter()
                .map(|p| PackageView {
                    name: p.name,
                    version: p.version,
                    what: p.what,
                    provides: p.headers.iter().chain(p.modules).copied().collect::<Vec<_>>().join(" "),
                })
                .collect(),
        })
        .collect();
    Ok(render(&EnvironmentsPage { nav, environments }))
}

/// The new-project form.
#[derive(Deserialize)]
pub struct ProjectForm {
    csrf_token: String,
    name: String,
    /// Private unless the form says otherwise, as a new repository is.
    #[serde(default = "private")]
    visibility: String,
}

fn private() -> String {
    "private".to_string()
}

/// `POST /projects`.
pub async fn create_project(
    State(state): State<AppState>,
    visitor: Visitor,
    PageForm(form): PageForm<ProjectForm>,
) -> PageResult {
    let user = visitor.check(&form.csrf_token)?;
    let project = crate::projects::create(&state, user, &form.name, &form.visibility).await?;
    Ok(Redirect::to(&format!("/projects/{}", project.name)).into_response())
}

struct ResultRow {
    id: String,
    commit: String,
    season: i64,
    created: String,
    status: String,
}

#[derive(Template)]
#[template(path = "project.html")]
struct ProjectPage {
    nav: Nav,
    name: String,
    full_name: String,
    visibility: &'static str,
    technique_type: String,
    comment: String,
    citation: String,
    /// Only the public description: the visitor cannot read the repository
    /// but the technique has published results.
    public_only: bool,
    clone_url: String,
    owner: bool,
    how_to: HowTo,
    results: Vec<ResultRow>,
    jobs: Vec<JobRow>,
}

/// `GET /projects/{name}`: the technique page (its info.json at the
/// latest commit) and its history. A visitor who cannot read the
/// repository still sees a technique with published results: its public
/// description (the info.json it was published with) and those results,
/// never its code or jobs.
pub async fn project_page(
    State(state): State<AppState>,
    Visitor(nav): Visitor,
    Path(name): Path<String>,
) -> PageResult {
    let (project, public_only) = match projects::readable(&state.pool, &name, nav.user.as_ref()).await {
        Ok(project) => (project, false),
        Err(hidden) => match projects::by_name(&state.pool, &name).await? {
            Some(project) => (project, true),
            None => return Err(hidden.into()),
        },
    };
    let owner = !public_only && nav.user.as_ref().is_some_and(|u| project.writable_by(u) || u.is_admin);
    let sets: Vec<_> = crate::results::of_project(&state.pool, &project.id)
        .await?
        .into_iter()
        .filter(|r| owner || r.is_public())
        .collect();
    let info = if public_only {
        // The newest published description; no published result, no page.
        let Some(set) = sets.iter().max_by_key(|r| r.published_at) else {
            // The same answer as for no project at all: a private name stays private.
            return Err(projects::not_found(&name).into());
        };
        serde_json::from_value::<fbksd_exchange::technique::TechniqueInfo>(set.info.clone()).ok()
    } else {
        match state.git.resolve(&project.id, "main").await {
            Some(commit) => crate::pipelines::sanity_check(&state, &project, &commit).await.ok(),
            None => None,
        }
    };
    let results = sets
        .into_iter()
        .map(|r| ResultRow {
            status: match (&r.hidden_reason, r.published_at) {
                (Some(_), _) => "hidden".into(),
                (None, Some(_)) => "published".into(),
                (None, None) => "private".into(),
            },
            id: r.id,
            commit: r.commit_sha[..12.min(r.commit_sha.len())].to_string(),
            season: r.season,
            created: when(r.created_at),
        })
        .collect();
    let jobs = match public_only {
        true => Vec::new(),
        false => crate::jobs::of_project(&state.pool, &project.id, 50).await?.iter().map(job_row).collect(),
    };
    let page = ProjectPage {
        full_name: info.as_ref().map(|i| i.full_name.clone()).unwrap_or_else(|| project.name.clone()),
        technique_type: info.as_ref().map(|i| format!("{:?}", i.technique_type).to_lowercase()).unwrap_or_default(),
        comment: info.as_ref().map(|i| i.comment.clone()).unwrap_or_default(),
        citation: info.as_ref().map(|i| i.citation.clone()).unwrap_or_default(),
        clone_url: state.clone_url(&project.name),
        how_to: how_to(&state, nav.user.as_ref(), Some(&project.name)),
        visibility: project.visibility.as_str(),
        public_only,
        name: project.name,
        owner,
        results,
        jobs,
        nav,
    };
    Ok(render(&page))
}

/// `POST /projects/{name}/run`: FBKSD_RUN at the head of `main`.
pub async fn run_project(
    State(state): State<AppState>,
    Path(name): Path<String>,
    Button { user, .. }: Button,
) -> PageResult {
    let project = projects::writable(&state.pool, &name, &user).await?;
    let commit =
        state.git.resolve(&project.id, "main").await.ok_or_else(|| {
            ApiError::bad_request("unknown_ref", format!("{name} has no commit on main yet: push first"))
        })?;
    let started = crate::pipelines::start(&state, &project, &user, &commit, "main", Request::Run, Source::Api).await?;
    Ok(Redirect::to(&format!("/jobs/{}", started.job.id)).into_response())
}

#[derive(Template)]
#[template(path = "job.html")]
struct JobPage {
    nav: Nav,
    job: JobRow,
    message: String,
    attempts: String,
    result_id: Option<String>,
    can_cancel: bool,
    live: bool,
    log: String,
}

/// `GET /jobs/{id}`: a job and its log, streamed live while it runs.
pub async fn job_page(State(state): State<AppState>, Visitor(nav): Visitor, Path(id): Path<String>) -> PageResult {
    let (job, project) = crate::jobs::readable(&state.pool, &id, nav.user.as_ref()).await?;
    let mut log: String = crate::jobs::log_since(&state.pool, &job.id, 0).await?.into_iter().map(|(_, t)| t).collect();
    // Others read a public project's job without its private result set.
    let job = match crate::results::private_result_of(&state.pool, &job, nav.user.as_ref()).await? {
        Some(private) => {
            log = crate::jobs::hide_result(&log, &private);
            job.without_result()
        }
        None => job,
    };
    let live = job.state.is_live();
    let can_cancel = live && nav.user.as_ref().is_some_and(|u| project.writable_by(u) || u.is_admin);
    let page = JobPage {
        job: job_row(&job),
        message: job.message.clone(),
        attempts: format!("{} of {}", job.attempts, job.max_attempts),
        result_id: job.result_id.clone(),
        can_cancel,
        live,
        log,
        nav,
    };
    Ok(render(&page))
}

/// `POST /jobs/{id}/cancel`.
pub async fn cancel_job(
    State(state): State<AppState>,
    Path(id): Path<String>,
    Button { user, .. }: Button,
) -> PageResult {
    crate::jobs::cancel_as(&state.pool, &id, &user).await?;
    Ok(Redirect::to(&format!("/jobs/{id}")).into_response())
}
