//! Projects: a technique's hosted git repository, its owner and its
//! visibility, and who may read or push it.

use crate::accounts::User;
use crate::error::ServiceError;
use crate::{now_ms, AppState};
use sqlx::{AnyPool, Row};

/// Who can see a project (its repository, pipelines and technique page).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Visibility {
    /// The owner (and administrators).
    Private,
    /// Every logged-in user.
    Internal,
    /// Everyone.
    Public,
}

impl Visibility {
    /// Parses `private`, `internal` or `public`.
    pub fn parse(text: &str) -> Result<Visibility, ServiceError> {
        match text {
            "private" => Ok(Visibility::Private),
            "internal" => Ok(Visibility::Internal),
            "public" => Ok(Visibility::Public),
            other => Err(ServiceError::invalid(
                "invalid_visibility",
                format!("visibility {other:?} is unknown: use private, internal or public"),
            )),
        }
    }
    /// The stored name.
    pub fn as_str(self) -> &'static str {
        match self {
            Visibility::Private => "private",
            Visibility::Internal => "internal",
            Visibility::Public => "public",
        }
    }
}

/// A project name: the same rules as a technique's `short_name`.
pub struct ProjectName(String);

impl ProjectName {
    /// Checks the rules.
    pub fn parse(text: &str) -> Result<ProjectName, ServiceError> {
        if fbksd_exchange::technique::is_valid_short_name(text) {
            Ok(ProjectName(text.to_string()))
        } else {
            Err(ServiceError::invalid(
                "invalid_name",
                format!("project name {text:?} must be 1 to 64 lower-case letters, digits, '-' or '_'"),
            ))
        }
    }
}

/// A project.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Project {
    /// Random id (also the repository's directory name).
    pub id: String,
    /// Unique name, in URLs.
    pub name: String,
    /// Owner's user id.
    pub owner_id: String,
    /// Who can see it.
    pub visibility: Visibility,
    /// Creation time, Unix ms.
    pub created_at: i64,
}

impl Project {
    /// Whether `user` (None: anonymous) may read the project.
    pub fn readable_by(&self, user: Option<&User>) -> bool {
        match (self.visibility, user) {
            (Visibility::Public, _) => true,
            (Visibility::Internal, Some(_)) => true,
            (Visibility::Private, Some(u)) => u.id == self.owner_id || u.is_admin,
            _ => false,
        }
    }
    /// Whether `user` may push, run pipelines and change the project.
    pub fn writable_by(&self, user: &User) -> bool {
        user.id == self.owner_id
    }
}

fn project_of(row: &sqlx::any::AnyRow) -> Result<Project, sqlx::Error> {
    let visibility: String = row.try_get("visibility")?;
    Ok(Project {
        id: row.try_get("id")?,
        name: row.try_get("name")?,
        owner_id: row.try_get("owner_id")?,
        visibility: Visibility::parse(&visibility).unwrap_or(Visibility::Private),
        created_at: row.try_get("created_at")?,
    })
}

const COLUMNS: &str = "id, name, owner_id, visibility, created_at";

/// Inserts a project row (the caller creates its repository).
pub async fn insert(
    pool: &AnyPool,
    owner: &User,
    name: &ProjectName,
    visibility: Visibility,
) -> Result<Project, ServiceError> {
    let project = Project {
        id: uuid::Uuid::new_v4().to_string(),
        name: name.0.clone(),
        owner_id: owner.id.clone(),
        visibility,
        created_at: now_ms(),
    };
    let inserted =
        sqlx::query("INSERT INTO projects (id, name, owner_id, visibility, created_at) VALUES ($1, $2, $3, $4, $5)")
            .bind(&project.id)
            .bind(&project.name)
            .bind(&project.owner_id)
            .bind(visibility.as_str())
            .bind(project.created_at)
            .execute(pool)
            .await;
    match inserted {
        Ok(_) => Ok(project),
        Err(sqlx::Error::Database(e)) if e.is_unique_violation() => Err(ServiceError::conflict(
            "name_taken",
            format!("a project named {:?} exists: choose another name", project.name),
        )),
        Err(e) => Err(e.into()),
    }
}

/// Names kept for the service's own projects.
const RESERVED_NAMES: &[&str] = &[crate::references::PROJECT];

/// Creates a project row and its repository, or neither.
pub async fn create(state: &AppState, owner: &User, name: &str, visibility: &str) -> Result<Project, ServiceError> {
    if RESERVED_NAMES.contains(&name) {
        return Err(ServiceError::conflict(
            "name_taken",
            format!("the project name {name:?} is kept for the service: choose another name"),
        ));
    }
    create_with_repository(state, owner, &ProjectName::parse(name)?, Visibility::parse(visibility)?).await
}

/// Creates the service account `owner`'s private project `name` (one of
/// the reserved names), with its repository.
pub async fn create_for_service(state: &AppState, owner: &User, name: &str) -> Result<Project, ServiceError> {
    create_with_repository(state, owner, &ProjectName::parse(name)?, Visibility::Private).await
}

async fn create_with_repository(
    state: &AppState,
    owner: &User,
    name: &ProjectName,
    visibility: Visibility,
) -> Result<Project, ServiceError> {
    let owned: i64 = sqlx::query_scalar("SELECT COUNT(*) FROM projects WHERE owner_id = $1")
        .bind(&owner.id)
        .fetch_one(&state.pool)
        .await?;
    let most = state.config.max_projects_per_user;
    if owned as u64 >= most {
        return Err(ServiceError::forbidden(
            "too_many_projects",
            format!("you own {owned} projects, the most one account may ({most}): {DELETE_OR_ASK}"),
        ));
    }
    let project = insert(&state.pool, owner, name, visibility).await?;
    if let Err(e) = state.git.create(&project.id).await {
        sqlx::query("DELETE FROM projects WHERE id = $1").bind(&project.id).execute(&state.pool).await?;
        state.git.delete(&project.id).await;
        return Err(ServiceError::internal(e));
    }
    Ok(project)
}

/// Deletes a project, its repository, jobs and unpublished result sets
/// (published ones stay on the leaderboard).
pub async fn delete(state: &AppState, project: &Project) -> Result<(), ServiceError> {
    for set in crate::results::of_project(&state.pool, &project.id).await? {
        if set.published_at.is_none() {
            crate::results::discard(&state.pool, &state.config.data_dir, &set.id).await?;
        }
    }
    sqlx::query("DELETE FROM projects WHERE id = $1").bind(&project.id).execute(&state.pool).await?;
    state.git.delete(&project.id).await;
    Ok(())
}

/// The project named `name`, if any.
pub async fn by_name(pool: &AnyPool, name: &str) -> Result<Option<Project>, sqlx::Error> {
    let row =
        sqlx::query(&format!("SELECT {COLUMNS} FROM projects WHERE name = $1")).bind(name).fetch_optional(pool).await?;
    row.as_ref().map(project_of).transpose()
}

/// The project with id `id`, if any.
pub async fn by_id(pool: &AnyPool, id: &str) -> Result<Option<Project>, sqlx::Error> {
    let row =
        sqlx::query(&format!("SELECT {COLUMNS} FROM projects WHERE id = $1")).bind(id).fetch_optional(pool).await?;
    row.as_ref().map(project_of).transpose()
}

/// The project named `name` if `user` may read it; otherwise 404, so
/// private names do not leak.
pub async fn readable(pool: &AnyPool, name: &str, user: Option<&User>) -> Result<Project, ServiceError> {
    match by_name(pool, name).await? {
        Some(p) if p.readable_by(user) => Ok(p),
        _ => Err(not_found(name)),
    }
}

/// The project named `name` if `user` may change it (403 if they may only read it).
pub async fn writable(pool: &AnyPool, name: &str, user: &User) -> Result<Project, ServiceError> {
    let project = readable(pool, name, Some(user)).await?;
    if project.writable_by(user) {
        Ok(project)
    } else {
        Err(ServiceError::forbidden("not_owner", format!("only the owner of {name} can do this")))
    }
}

/// 404 for a project.
pub fn not_found(name: &str) -> ServiceError {
    ServiceError::not_found(format!("no project named {name:?} that you can see"))
}

/// Projects listed on one page ([`visible`]).
pub const PAGE: usize = 100;

/// Projects `user` can see (all of theirs, and others' internal and public
/// ones), by name, after the name `after`: at most [`PAGE`] of them and
/// whether more follow. Chosen by the database, so a list of many
/// projects costs one page's rows, whoever asks.
pub async fn visible(pool: &AnyPool, user: Option<&User>, after: &str) -> Result<(Vec<Project>, bool), sqlx::Error> {
    let (seen, owner) = match user {
        None => ("visibility = 'public'", ""),
        Some(u) if u.is_admin => ("1 = 1", ""),
        Some(u) => ("(visibility <> 'private' OR owner_id = $3)", u.id.as_str()),
    };
    let sql = format!("SELECT {COLUMNS} FROM projects WHERE name > $1 AND {seen} ORDER BY name LIMIT $2");
    let mut query = sqlx::query(&sql).bind(after).bind(PAGE as i64 + 1);
    if !owner.is_empty() {
        query = query.bind(owner);
    }
    let rows = query.fetch_all(pool).await?;
    let mut projects = rows.iter().map(project_of).collect::<Result<Vec<Project>, _>>()?;
    let more = projects.len() > PAGE;
    projects.truncate(PAGE);
    Ok((projects, more))
}

/// What to do when an account has reached what it may own.
pub const DELETE_OR_ASK: &str =
    "delete a project you no longer need (its published results stay on the board) or ask the administrator for more";

/// What the repositories of `owner_id`'s projects hold together, and the
/// most they may (`max_repository_mib_per_user`): a push to any of them is
/// weighed against it.
pub async fn repository_quota(state: &AppState, owner_id: &str) -> Result<crate::git::RepositoryQuota, sqlx::Error> {
    let ids = ids_of_owner(&state.pool, owner_id).await?;
    Ok(crate::git::RepositoryQuota {
        used_bytes: state.git.repositories_bytes(ids).await,
        max_bytes: state.config.max_repository_mib_per_user.saturating_mul(1 << 20),
    })
}

/// Ids of a user's projects (to delete their repositories with the account).
pub async fn ids_of_owner(pool: &AnyPool, owner_id: &str) -> Result<Vec<String>, sqlx::Error> {
    let rows = sqlx::query("SELECT id FROM projects WHERE owner_id = $1").bind(owner_id).fetch_all(pool).await?;
    rows.iter().map(|r| r.try_get("id")).collect()
}
