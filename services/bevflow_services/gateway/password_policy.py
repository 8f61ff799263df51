"""Which passwords are accepted: long enough, not one everybody tries first, not the user's name.

Length counts most; the list of common passwords is short on purpose (the ones that pass the
length rule and lead every guessing list), and a password of few distinct characters
(``aaaaaaaaaa``, ``abababababab``) is as weak as a short one.

>>> check_password("correct horse battery", "ana")
'correct horse battery'
>>> check_password("aaaaaaaaaaaa")  # doctest: +IGNORE_EXCEPTION_DETAIL
Traceback (most recent call last):
PasswordError: a password needs at least 4 different characters
"""

from __future__ import annotations

MIN_PASSWORD = 10
MIN_DISTINCT = 4
COMMON_PASSWORDS = frozenset({
    "0123456789", "1234567890", "12345678910", "123456789a", "1q2w3e4r5t", "1qaz2wsx3edc", "abcdefghij",
    "administrator", "asdfghjkl1", "bevflow123", "changeme123", "iloveyou123", "letmein123", "password1!",
    "password12", "password123", "password1234", "passw0rd123", "qwerty1234", "qwertyuiop", "qwertyuiop1",
    "welcome123", "zaq12wsxcde",
})


class PasswordError(ValueError):
    """A password that is not acceptable; the message says why."""


def check_password(password: str, name: str = "") -> str:
    """``password`` if the policy accepts it for user ``name``; ``PasswordError`` saying why not."""
    if len(password) < MIN_PASSWORD:
        raise PasswordError(f"a password needs at least {MIN_PASSWORD} characters")
    if len(set(password)) < MIN_DISTINCT:
        raise PasswordError(f"a password needs at least {MIN_DISTINCT} different characters")
    if password.casefold() in COMMON_PASSWORDS:
        raise PasswordError("that password is among the first that anyone guessing would try")
    if name and name.casefold() in password.casefold():
        raise PasswordError("a password may not contain the user's name")
    return password
