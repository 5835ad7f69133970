"""The live ground station (issue 15): watch an episode in the browser as it flies, pause it, stop it, fly it.

    control.py   pause, emergency stop, take-over and hand back: the hook the episode loop consults per step
    feed.py      reads a run directory as it grows (the page is a view of the run's files)
    plan.py      the floor plan image and its world-to-pixel bounds
    app.py       the FastAPI app: the page, Server-Sent Events, frames, POST /api/control
    station.py   serves the app from a background thread (run --live) or in the foreground (watch)
"""
