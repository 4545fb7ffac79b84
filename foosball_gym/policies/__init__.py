"""The scripted players: the keeper and the team that aim, shoot and defend, the shots they
meet, and the rungs of the games' scripted ladder."""
