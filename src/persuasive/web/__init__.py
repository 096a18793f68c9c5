"""Drive against the planner in a browser: the user-study server of ``persuasive drive``.

A person drives the human vehicle (HV) with the arrow keys, on-screen pedals or a gamepad; the
AV's planner decides as in ``persuasive simulate``; the server is the clock (one step every
``dt``) and records every trial as a run record plus the person's inputs and the timings.

- :mod:`.study`: the study file, its conditions, the balanced Latin square that orders them
  per participant (no web dependency);
- :mod:`.human`: the person as the HV's policy (:class:`~.human.LiveHuman`);
- :mod:`.scene`: what the page draws (scene geometry, poses), for every scenario;
- :mod:`.session`: one participant's session: the protocol, the clock, the files;
- :mod:`.server`: the Starlette app (routes, token, origin and host rules) and running it;
- ``static/``: the page (``index.html``, ``drive.js``, ``drive.css``), package data.

The server needs the ``web`` extra (``pip install -e '.[web]'`` in the checkout: Starlette, uvicorn,
websockets); the study module does not.
"""

from .study import Study, balanced_latin_square, default_study, load_study

__all__ = ["Study", "balanced_latin_square", "default_study", "load_study"]
