"""TableTeach: teach robots ordered tasks from demonstrations and assessments."""
