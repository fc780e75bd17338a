"""Changing a user's role (the admin's Users page): checked and audited like every service call.

A separate module so the service's users section stays as it is (another change edits
``patients/service.py``); it uses the record's own transaction, permission check and audit.
"""
from __future__ import annotations

from typing import Any

from patients.roles import Action, Role
from patients.service import Actor, ClinicalRecord, _enum, _user, _user_dict
from rt.errors import InputError


def set_user_role(record: ClinicalRecord, actor: Actor, username: str,
                  role: Role | str) -> dict[str, Any]:
    """Give ``username`` the role ``role`` (admin only); the user's dict after the change.

    Refuses an admin changing their own role: the acting admin stays one, so the record is
    never left without anyone able to manage accounts.
    """
    new: Role = _enum(Role, role, "role")
    with record._tx() as db:
        record._require(db, actor, Action.USERS_MANAGE)
        user = _user(db, username)
        if username == actor.username:
            raise InputError("an admin cannot change their own role (ask another admin)")
        before = user.role
        if before == new.value:
            return _user_dict(user)
        user.role = new.value
        record._audit(db, actor, "user.role", "user", username, before={"role": before},
                      after={"role": new.value})
        db.flush()
        return _user_dict(user)
