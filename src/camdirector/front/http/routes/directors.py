"""REST route of the match directors a MATCH session may name, for the dashboard's director choice.

    GET /v1/match-directors   {"directors": [{"name": "planned", "label": "...", "wire": "MATCH_DIRECTOR_PLANNED"},
                                             ...]}

Read from the one registry (pipeline/match/director_registry.py), in its order: ours, the
baselines, then the directors of the server's plugins (`camdirector serve --plugin`), whose
"wire" is null: a style names them by `match_director_name`. Its verb is `session.read`: whoever
may read a session's style may read what it may name.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends
from pydantic import BaseModel, Field

from camdirector.access.guard import Identity
from camdirector.access.roles import Verb
from camdirector.front.http.auth import require
from camdirector.pipeline.match.director_registry import registered


class DirectorOut(BaseModel):
    name: str = Field(description="what Style.match_director_name names it by")
    label: str = Field(description="one line for a person choosing it")
    wire: str | None = Field(description="its camdirector.v1.MatchDirector value; null for a plugin's")


class DirectorList(BaseModel):
    directors: list[DirectorOut]


def build_director_router() -> APIRouter:
    routes = APIRouter(prefix="/v1/match-directors", tags=["sessions"])

    @routes.get("", response_model=DirectorList)
    def list_directors(identity: Annotated[Identity, Depends(require(Verb.SESSION_READ))]) -> DirectorList:
        """Every registered match director, in the registry's order."""
        return DirectorList(directors=[DirectorOut(name=e.name, label=e.label, wire=e.wire) for e in registered()])

    return routes
