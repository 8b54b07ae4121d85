//! The database: one [`sqlx::AnyPool`] over SQLite or PostgreSQL, chosen by
//! URL, and one portable schema (`server/migrations/`) applied at start.
//! Queries use `$1`-style parameters, which both drivers accept.

use sqlx::any::AnyPoolOptions;
use sqlx::AnyPool;

/// Connects to `url` and brings the schema up to date.
pub async fn connect(url: &str) -> Result<AnyPool, sqlx::Error> {
    sqlx::any::install_default_drivers();
    let sqlite = url.starts_with("sqlite:");
    let pool = AnyPoolOptions::new()
        // SQLite serialises writers anyway; one connection avoids "database is locked".
        .max_connections(if sqlite { 1 } else { 16 })
        .after_connect(move |conn, _| {
            Box::pin(async move {
                if sqlite {
                    sqlx::query("PRAGMA foreign_keys = ON").execute(&mut *conn).await?;
                }
                Ok(())
            })
        })
        .connect(url)
        .await?;
    sqlx::migrate!("./migrations").run(&pool).await?;
    Ok(pool)
}
