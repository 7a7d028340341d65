"""Roads: what the rig's road motor is commanded to follow: the ``--road`` values and their
profiles (ISO 8608, chirp and sine, a bump, a recorded file).
"""
